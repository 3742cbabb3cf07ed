"""Whether the store can take a write now, answered cheaply and within a deadline.

The check never writes while writes succeed. It reads one row (is the
database there?), on SQLite compares the free space of the database's file
system with a floor, and looks at the outcome of the last write the service
made. Only after a write failed does it write a probe row, to learn when
writes work again (a load balancer that stops sending traffic to the instance
would otherwise never let it find out). Concurrent probes share one check, so
a hung database holds at most one thread of them; the answer comes within the
deadline either way.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

from routing_svc.errors import StorageError
from routing_svc.store import EventLog
from routing_svc.store.engine import fault_reason

__all__ = ["StoreHealth", "StoreVerdict"]


@dataclass(frozen=True, slots=True)
class StoreVerdict:
    """The answer of one check: ``reason`` is ``None`` when writes would succeed."""

    reason: str | None
    connections_in_use: int


class StoreHealth:
    """Checks of one event log, one at a time, each bounded by ``timeout_s``.

    Parameters
    ----------
    log
        The service's event log.
    timeout_s
        The deadline of a check, in seconds.
    min_free_bytes
        Below this many free bytes (SQLite), the store counts as full.
    """

    def __init__(self, log: EventLog, *, timeout_s: float, min_free_bytes: int) -> None:
        self.log = log
        self.timeout_s = timeout_s
        self.min_free_bytes = min_free_bytes
        self._running: asyncio.Future[str | None] | None = None

    async def check(self) -> StoreVerdict:
        """Check now (or join the check running); answer within the deadline."""
        if self._running is None or self._running.done():
            self._running = asyncio.ensure_future(asyncio.to_thread(self._reason))
        try:
            async with asyncio.timeout(self.timeout_s):
                reason = await asyncio.shield(self._running)
        except TimeoutError:
            reason = f"the store did not answer within {self.timeout_s:g} s"
        return StoreVerdict(reason, self.log.connections_in_use())

    def _reason(self) -> str | None:
        try:
            self.log.check_reachable()
        except StorageError as error:
            return fault_reason(error)
        free = self.log.free_bytes()
        if free is not None and free < self.min_free_bytes:
            return f"the store is out of space ({free} bytes free)"
        if self.log.last_write_error is not None:
            try:
                self.log.probe_write()
            except StorageError as error:
                return fault_reason(error)
        return None
