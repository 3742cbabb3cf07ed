"""One write request on its way to a group commit, and the future that answers it.

A request joins a writer's queue as a :class:`QueuedWrite`; its caller holds
its :data:`PendingAnswer`, a future answered exactly once, only after the
request's transaction committed (or with the request's error).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future

from routing_svc.service.runtime import FleetRuntime
from routing_svc.store import NewEvent

__all__ = [
    "GROUP_CAP",
    "Answer",
    "Compute",
    "Holds",
    "PendingAnswer",
    "QueuedWrite",
    "fail_unfinished",
    "take_batch",
]

GROUP_CAP = 256
"""At most this many targets (or other events) are committed in one group."""

Compute = Callable[[FleetRuntime], list[NewEvent]]
"""``compute(runtime) -> new events``: applies one request to the runtime."""

Answer = tuple[list[str], int]
"""Each event's result JSON, and the ``seq`` of the request's last event."""

PendingAnswer = Future[Answer] | asyncio.Future[Answer]
"""The future of a queued request: the event loop's own for a request made on it."""


class QueuedWrite:
    """One write request waiting in a writer's queue.

    Its future is a :class:`concurrent.futures.Future`, or, for a request made
    on an event loop (``loop``), a future of that loop: it is answered there
    without a trip through another thread. Either way it is answered exactly
    once, by :meth:`resolve` or :meth:`fail`, from any thread.

    Parameters
    ----------
    fleet_id
        The fleet.
    compute
        Applies the request to the fleet's runtime and returns its events.
    key, digest
        The request's idempotency key and request hash (or ``None``).
    size
        How many events the request will write, counted against :data:`GROUP_CAP`.
    loop
        The event loop the request was made on, ``None`` for another thread.
    """

    __slots__ = (
        "compute",
        "digest",
        "fleet_id",
        "future",
        "key",
        "loop",
        "settled",
        "size",
        "thread",
    )

    def __init__(
        self,
        fleet_id: str,
        compute: Compute,
        key: str | None,
        digest: str | None,
        size: int,
        loop: asyncio.AbstractEventLoop | None = None,
    ) -> None:
        self.fleet_id = fleet_id
        self.compute = compute
        self.key = key
        self.digest = digest
        self.size = size
        self.loop = loop
        self.settled = False
        """Whether the request was answered (or withdrawn): nothing may answer it again."""
        self.future: PendingAnswer
        if loop is None:
            self.future = Future()
            self.future.set_running_or_notify_cancel()  # queued means running: no cancelling
        else:
            self.future = loop.create_future()
            self.thread = threading.get_ident()

    def resolve(self, answer: Answer) -> None:
        """Answer the request (unless it was answered already)."""
        self._settle(answer, None)

    def fail(self, error: BaseException) -> None:
        """Fail the request with ``error`` (unless it was answered already)."""
        self._settle(None, error)

    def _settle(self, answer: Answer | None, error: BaseException | None) -> None:
        if self.settled:
            return
        self.settled = True
        if self.loop is None or threading.get_ident() == self.thread:
            _set_future(self.future, answer, error)
        else:
            with contextlib.suppress(RuntimeError):  # a closed loop has no one waiting
                self.loop.call_soon_threadsafe(_set_future, self.future, answer, error)


def _set_future(future: PendingAnswer, answer: Answer | None, error: BaseException | None) -> None:
    """Set the outcome of a request's future; a loop's future that its waiter cancelled
    (the client went away) takes none."""
    if future.cancelled():
        return
    if error is not None:
        future.set_exception(error)
    else:
        future.set_result(answer)  # type: ignore[arg-type]


Holds = Callable[[str, int], bool]
"""``holds(fleet_id, events_ahead)``: whether a fleet's request that brings its events in
the batch to ``events_ahead`` must stay queued for now."""


def take_batch(queue: deque[QueuedWrite], holds: Holds | None = None) -> list[QueuedWrite]:
    """Take the next batch from a non-empty ``queue``: its oldest requests, up to
    :data:`GROUP_CAP` events.

    A fleet that ``holds`` keeps that request and every later one of its own queued,
    in order, while the other fleets' requests are taken. The batch holds at least one
    request unless every fleet queued is held.
    """
    batch: list[QueuedWrite] = []
    total = 0
    ahead: dict[str, int] = {}
    held: list[QueuedWrite] = []
    held_fleets: set[str] = set()
    while queue:
        pending = queue[0]
        if batch and total + pending.size > GROUP_CAP:
            break
        queue.popleft()
        fleet_id = pending.fleet_id
        events = ahead.get(fleet_id, 0) + pending.size
        if holds is not None and (fleet_id in held_fleets or holds(fleet_id, events)):
            held_fleets.add(fleet_id)
            held.append(pending)
            continue
        ahead[fleet_id] = events
        batch.append(pending)
        total += pending.size
    queue.extendleft(reversed(held))
    return batch


def fail_unfinished(batch: list[QueuedWrite], error: BaseException) -> None:
    """Fail every request of ``batch`` that has no answer yet."""
    for pending in batch:
        pending.fail(error)
