"""The hot route ``POST /v1/fleets/{id}/targets`` served straight from the ASGI layer.

A target's search and update are cheap next to FastAPI's request machinery
(routing, dependency resolution, response classes); ``bench/http_throughput.py``
measures the difference, head to head. :class:`TargetFastPath` is the
innermost of the application's own middleware (``create_app`` adds it first),
so the :class:`~routing_svc.service.guards.Guards` (API key, body limit) and the
request deadline apply unchanged. It answers the common case itself: a valid
body for a fleet that is in memory. It takes the route's rules from their one
definition (:mod:`routing_svc.service.target_route`: the path, how a target is
queued; :mod:`routing_svc.service.deps`: the key's bounds), parses the body with
the same pydantic model and answers with the same bytes.

Everything else goes on to the FastAPI route, with the body replayed: an
invalid body or header, a fleet that must first be read from the database,
or an error raised before anything was queued. The route then answers as it
always does (the same problem+json), and nothing was applied twice because
nothing was applied yet. Domain errors that come back from the writer (an
unreachable target, an idempotency key reused with another body, a store
failure or the request's deadline) are answered here with the route's
problem+json (:func:`~routing_svc.service.problems.error_problem`).
The route stays registered, so the OpenAPI document describes this path.
"""

from __future__ import annotations

import asyncio

from prometheus_client import Counter
from pydantic import ValidationError
from starlette.types import ASGIApp, Receive, Scope, Send

from routing_svc.errors import RoutingSvcError
from routing_svc.service.deadline import request_deadline
from routing_svc.service.deps import usable_idempotency_key
from routing_svc.service.fleets import FleetService
from routing_svc.service.guards import replaying
from routing_svc.service.problems import error_problem, retry_after_of
from routing_svc.service.schemas import TargetSpec
from routing_svc.service.target_route import TARGET_PATH, TARGETS_APPLIED, submit_target

IDEMPOTENCY_HEADER = b"idempotency-key"

_JSON_HEADERS = (b"content-type", b"application/json")

FAST_PATH_ANSWERS = Counter(
    "routing_svc_target_fast_path_total",
    "Single-target requests answered by the ASGI fast path (the rest by the FastAPI route)",
)


class TargetFastPath:
    """Serve valid single targets for cached fleets; pass every other request on."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "POST":
            await self.app(scope, receive, send)
            return
        match = TARGET_PATH.match(scope["path"])
        service: FleetService | None = getattr(scope["app"].state, "fleets", None)
        if match is None or service is None or not service.is_cached(match["fleet_id"]):
            await self.app(scope, receive, send)
            return
        usable, key = _idempotency_key(scope)
        body = await _read_body(receive)
        if body is None:  # the client went away
            return
        replay = replaying(body, receive)
        if not usable:
            await self.app(scope, replay, send)
            return
        try:
            target = TargetSpec.model_validate_json(body)
        except ValidationError:
            await self.app(scope, replay, send)
            return
        try:
            loop = asyncio.get_running_loop()
            queued = submit_target(service, match["fleet_id"], target, key, loop)
        except RoutingSvcError:  # raised before anything was queued: the route answers
            await self.app(scope, replay, send)
            return
        try:
            results, _ = await service.settled(queued, deadline=request_deadline())
        except RoutingSvcError as error:
            response = error_problem(error, retry_after=retry_after_of(scope["app"]))
            await response(scope, replay, send)
            FAST_PATH_ANSWERS.inc()
            return
        TARGETS_APPLIED.inc()
        FAST_PATH_ANSWERS.inc()
        answer = results[0].encode()
        await send(
            {
                "type": "http.response.start",
                "status": 200,
                "headers": [(b"content-length", str(len(answer)).encode()), _JSON_HEADERS],
            }
        )
        await send({"type": "http.response.body", "body": answer})


def _idempotency_key(scope: Scope) -> tuple[bool, str | None]:
    """Whether the route would accept the request's ``Idempotency-Key`` (it rejects an
    empty or too long key, and this path leaves a repeated header to it), and the key
    (``None`` without one)."""
    values = [value for name, value in scope["headers"] if name == IDEMPOTENCY_HEADER]
    if not values:
        return True, None
    key = values[0].decode("latin-1")
    return len(values) == 1 and usable_idempotency_key(key), key


async def _read_body(receive: Receive) -> bytes | None:
    """The whole request body, or ``None`` if the client disconnected."""
    chunks: list[bytes] = []
    while True:
        message = await receive()
        if message["type"] == "http.disconnect":
            return None
        chunks.append(message.get("body", b""))
        if not message.get("more_body", False):
            return b"".join(chunks)
