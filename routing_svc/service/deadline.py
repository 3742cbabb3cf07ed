"""The deadline of a request, and what the client gets when it passes.

:class:`RequestDeadline` sits inside the guards (the body has been read), so
the deadline counts the service's own work and its waits on the store, not a
slow client. The routes that wait on a write read the deadline
(:func:`request_deadline`) and answer themselves when it passes, telling a
write that was never taken by the writer (:class:`~routing_svc.errors.StorageTimeout`)
from one that may have committed
(:class:`~routing_svc.errors.CommitOutcomeUnknown`). For every other route the
middleware answers shortly after: a read with ``StorageTimeout``, a write with
``CommitOutcomeUnknown``. Either way: 503 problem+json with ``Retry-After``.

Network uploads (parsing is CPU work, bounded by the upload limit) and the
event stream (open by design) have no deadline; their waits on the store are
bounded by the store's own timeouts. For the same reason a route pauses its
deadline while it solves (:func:`deadline_paused`: a fleet's optimum, bounded by
its network and candidate sites): the deadline moves on by the time solved, so
it still bounds every wait on the store before and after.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from contextvars import ContextVar

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from routing_svc.errors import CommitOutcomeUnknown, StorageError, StorageTimeout
from routing_svc.service.guards import READ_METHODS
from routing_svc.service.problems import error_problem

__all__ = ["GRACE_S", "RequestDeadline", "deadline_paused", "request_deadline"]

GRACE_S = 0.05
"""How long after the deadline the middleware answers for a route that did not."""

_DEADLINE: ContextVar[float | None] = ContextVar("routing_svc_request_deadline", default=None)
_BOUND: ContextVar[asyncio.Timeout | None] = ContextVar("routing_svc_request_bound", default=None)


def request_deadline() -> float | None:
    """The current request's deadline (event-loop time), ``None`` outside one."""
    return _DEADLINE.get()


@asynccontextmanager
async def deadline_paused() -> AsyncIterator[None]:
    """Stop the current request's deadline while the block runs, then move it on by
    the time the block took (nothing outside a request)."""
    deadline, bound = _DEADLINE.get(), _BOUND.get()
    if deadline is None or bound is None:
        yield
        return
    loop = asyncio.get_running_loop()
    started = loop.time()
    bound.reschedule(None)
    try:
        yield
    finally:
        moved = deadline + (loop.time() - started)
        _DEADLINE.set(moved)
        bound.reschedule(moved + GRACE_S)


def _exempt(scope: Scope) -> bool:
    path: str = scope["path"].rstrip("/")
    return path.endswith("/stream") or (scope["method"] == "POST" and path == "/v1/networks")


class RequestDeadline:
    """Answer 503 (``Retry-After``) when a request's deadline passes before its answer.

    Parameters
    ----------
    app
        The application.
    timeout_s
        Seconds from the request's arrival here to its deadline.
    retry_after_s
        The answer's ``Retry-After``.
    """

    def __init__(self, app: ASGIApp, *, timeout_s: float, retry_after_s: int) -> None:
        self.app = app
        self.timeout_s = timeout_s
        self.retry_after_s = retry_after_s

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or _exempt(scope):
            await self.app(scope, receive, send)
            return
        deadline = asyncio.get_running_loop().time() + self.timeout_s
        token = _DEADLINE.set(deadline)
        started = False

        async def tracked(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        bound = asyncio.timeout_at(deadline + GRACE_S)
        bound_token = _BOUND.set(bound)
        try:
            async with bound:
                await self.app(scope, receive, tracked)
        except TimeoutError:
            if not bound.expired() or started:
                raise
            error: StorageError
            if scope["method"] in READ_METHODS:
                error = StorageTimeout(f"{scope['method']} {scope['path']} passed its deadline")
            else:
                error = CommitOutcomeUnknown(
                    f"{scope['method']} {scope['path']} passed its deadline while it ran"
                )
            await error_problem(error, retry_after=self.retry_after_s)(scope, receive, send)
        finally:
            _BOUND.reset(bound_token)
            _DEADLINE.reset(token)
