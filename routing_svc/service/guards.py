"""ASGI guards in front of every route: body size limits and the API key.

They are middleware, not per-route dependencies, so that a new write route
cannot forget them: every request whose method changes state (anything but
GET, HEAD and OPTIONS) needs the key when one is configured.
"""

from __future__ import annotations

import hmac
import json

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from routing_svc.service.problems import PROBLEM

READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


async def send_problem(send: Send, status: int, title: str, detail: str) -> None:
    """Answer with a problem+json document straight from the ASGI layer."""
    slug = title.lower().replace(" ", "-")
    body = json.dumps(
        {
            "type": f"urn:routing-svc:problem:{slug}",
            "title": title,
            "status": status,
            "detail": detail,
        }
    ).encode()
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [
                (b"content-type", PROBLEM.encode()),
                (b"content-length", str(len(body)).encode()),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})


class Guards:
    """Body size limit (per path: uploads get their own) and the optional API key."""

    def __init__(
        self,
        app: ASGIApp,
        *,
        max_body_bytes: int,
        max_upload_bytes: int,
        api_key: str | None,
    ) -> None:
        self.app = app
        self.max_body = max_body_bytes
        self.max_upload = max_upload_bytes
        self.api_key = api_key.encode() if api_key else None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        method: str = scope["method"]
        headers = dict(scope.get("headers") or [])
        if self.api_key is not None and method not in READ_METHODS:
            given = headers.get(b"x-api-key", b"")
            if not hmac.compare_digest(given, self.api_key):
                await send_problem(send, 401, "Unauthorized", "this route needs a valid X-API-Key")
                return
        if method in READ_METHODS:
            await self.app(scope, receive, send)
            return
        upload = scope["path"].rstrip("/") == "/v1/networks"
        limit = self.max_upload if upload else self.max_body
        declared = headers.get(b"content-length")
        if declared is not None:
            try:
                too_large = int(declared) > limit
            except ValueError:
                await send_problem(send, 400, "Bad request", "invalid Content-Length")
                return
            if too_large:
                await send_problem(
                    send, 413, "Payload too large", f"the body exceeds the limit of {limit} bytes"
                )
                return
        if upload:
            # uploads stream straight to their route, which counts the bytes itself
            # (see routes/networks.py): buffering them here would hold them twice
            await self.app(scope, receive, send)
            return
        chunks: list[bytes] = []
        received = 0
        more = True
        while more:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            chunk = message.get("body", b"")
            received += len(chunk)
            if received > limit:
                await send_problem(
                    send, 413, "Payload too large", f"the body exceeds the limit of {limit} bytes"
                )
                return
            chunks.append(chunk)
            more = bool(message.get("more_body", False))
        body = b"".join(chunks)
        await self.app(scope, replaying(body, receive), send)


def replaying(body: bytes, receive: Receive) -> Receive:
    """A ``receive`` that gives the already-read ``body`` once, then what ``receive`` gives."""
    delivered = False

    async def replay() -> Message:
        nonlocal delivered
        if not delivered:
            delivered = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replay
