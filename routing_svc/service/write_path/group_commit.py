"""Group commit: write requests of many clients and fleets, durable with one ``fsync``.

A write request joins a queue and gets a :data:`PendingAnswer`; a writer takes
everything queued (up to :data:`GROUP_CAP` events) and commits the requests of
all fleets in it in one transaction
(:meth:`~routing_svc.store.event_log.EventLog.append_groups`), so one ``fsync``
acknowledges them all.

There are two writers. Requests made on an event loop's thread (the REST API's target
routes) are written *by that event loop* on SQLite: it computes the group and stages its
transaction itself, without waiting for any lock, and only the commit (the ``fsync``)
runs on a worker thread, while the loop goes on serving requests. The targets' Python
work thus stays on one thread instead of passing the interpreter lock back and forth
with a writer thread for every target. The loop hands the interpreter lock to the
committer for the few microseconds it needs to start the commit
(:mod:`~routing_svc.service.write_path.committer`): CPython would otherwise let it run
only when the loop next idles, after the loop parsed the next requests, so the disk's
wait would follow that work instead of overlapping it. When staging is not possible at
once (another thread or process holds the write lock, a fleet's lock is taken, a fleet
is not in memory, a fleet's targets could wait for its consolidation's solve), the group
goes to a worker thread as a whole. Every other request (from worker threads, and all of
them on PostgreSQL, whose statements wait on the network) joins the queue of the writer
thread.

Under each fleet's lock the cached :class:`FleetRuntime` first replays the
events other workers (or hosts) wrote since it last looked, then computes
each request's events in queue order; a request that fails with a domain
error fails alone. Every answer is given only after the transaction
committed. If the shared transaction fails, each fleet's requests are
committed on their own, so one fleet's trouble cannot fail another's
requests; a cache that may have diverged (an append that failed after
computing) is dropped and rebuilt from the log.

A fleet whose next targets would wait for its consolidation's solve (solved in a
worker process, :mod:`~routing_svc.service.background_solver`) is held: its requests
stay queued, in order, and the writers take the other fleets' meanwhile; the solve's
end wakes them. So one fleet's wait never holds another fleet or the event loop. A
request that itself passes the point where a consolidation falls due and the point by
which it must be applied (the epoch's first is applied at once) waits inside its
transaction, on a worker thread: the event loop goes on answering, and the writes queued
behind it follow it.

The domain provides the fleets' runtimes and locks (:class:`FleetRuntimes`);
it knows nothing else of how its requests are written.
"""

from __future__ import annotations

import asyncio
import threading
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future
from contextlib import ExitStack, contextmanager, suppress
from typing import Any, Protocol

from prometheus_client import Counter, Histogram

from routing_svc.errors import (
    CommitOutcomeUnknown,
    RoutingSvcError,
    StorageError,
    StorageTimeout,
)
from routing_svc.service.runtime import FleetRuntime
from routing_svc.service.write_path.committer import Committer
from routing_svc.service.write_path.pending import (
    Answer,
    Compute,
    PendingAnswer,
    QueuedWrite,
    fail_unfinished,
    take_batch,
)
from routing_svc.store import EventLog, EventRecord, FleetGroup, GroupItem, NewEvent

__all__ = ["SNAPSHOT_EVERY", "FleetRuntimes", "GroupCommit"]

HELD_RECHECK_S = 1.0
"""How often a writer looks again at fleets it holds back for their consolidation (their
solve's end wakes it anyway)."""

SNAPSHOT_EVERY = 64
"""A snapshot of a small fleet's state is stored whenever its version crosses a multiple
of this (:meth:`~routing_svc.service.runtime.FleetRuntime.snapshot_every`)."""

COMMIT_GROUP_SIZE = Histogram(
    "routing_svc_commit_group_size",
    "Write requests committed together in one transaction (group commit)",
    buckets=(1, 2, 4, 8, 16, 32, 64, 128, 256),
)

COMMITS = Counter(
    "routing_svc_commits_total",
    "Transactions of write requests committed, by the writer that staged them",
    ["writer"],
)


class FleetRuntimes(Protocol):
    """The fleets' runtimes and locks, as the domain keeps them."""

    def lock_of(self, fleet_id: str) -> threading.Lock:
        """The lock under which a fleet's runtime is read and changed."""
        ...

    def is_cached(self, fleet_id: str) -> bool:
        """Whether the fleet's runtime is in memory."""
        ...

    def consolidation_wait(self, fleet_id: str, targets_ahead: int) -> Future[Any] | None:
        """The consolidation solve that the fleet's next ``targets_ahead`` targets would
        wait for, ``None`` if none (or the fleet is not in memory)."""
        ...

    def solves_within(self, fleet_id: str, targets_ahead: int) -> bool:
        """Whether one of the fleet's next ``targets_ahead`` targets could wait for a
        consolidation's solve (one already handed over, or one that falls due among
        them); called under its lock."""
        ...

    def runtime_for_write(self, fleet_id: str) -> FleetRuntime:
        """The fleet's runtime, loaded if it is not in memory, not caught up with the
        log (the append hands over what it missed); called under its lock."""
        ...

    def catch_up(self, runtime: FleetRuntime, events: Sequence[EventRecord]) -> None:
        """Replay the ``events`` after the runtime's version."""
        ...

    def forget(self, fleet_id: str) -> None:
        """Drop a runtime that may have diverged from the log; it is rebuilt from it."""
        ...


class _Diverged(Exception):
    """A request failed after changing the runtime: nothing may be written."""


class _FleetShare:
    """One fleet's share of a commit: its runtime, requests and answers."""

    def __init__(self, runtimes: FleetRuntimes, fleet_id: str, group: list[QueuedWrite]) -> None:
        self.runtimes = runtimes
        self.fleet_id = fleet_id
        self.group = group
        self.runtime = runtimes.runtime_for_write(fleet_id)
        self.before = self.runtime.version
        self.diverged: list[QueuedWrite] = []

    def build(
        self, missed: list[EventRecord], fresh: list[int]
    ) -> list[list[NewEvent] | RoutingSvcError]:
        runtime = self.runtime
        self.runtimes.catch_up(runtime, missed)
        self.before = runtime.version
        out: list[list[NewEvent] | RoutingSvcError] = []
        for index in fresh:
            at = runtime.version
            pending = self.group[index]
            try:
                out.append(pending.compute(runtime))
            except RoutingSvcError as exc:
                if runtime.version != at:
                    self.diverged.append(pending)
                    pending.fail(exc)
                    raise _Diverged(str(exc)) from exc
                out.append(exc)
        return out

    def snapshot(self, version: int) -> str | None:
        every = self.runtime.snapshot_every(SNAPSHOT_EVERY)
        due = version // every != self.before // every
        return self.runtime.snapshot_json() if due else None

    def request(self) -> FleetGroup:
        return FleetGroup(
            self.fleet_id,
            self.runtime.version,
            tuple((p.key, p.digest) for p in self.group),
            self.build,
            self.snapshot,
        )

    def settle(self, items: list[GroupItem]) -> None:
        """Answer every request from its :class:`GroupItem`."""
        COMMIT_GROUP_SIZE.observe(len(self.group))
        for pending, item in zip(self.group, items, strict=True):
            if item.error is not None:
                pending.fail(item.error)
            else:
                last = item.events[-1].seq if item.events else item.version
                pending.resolve(([e.result_json or "{}" for e in item.events], last))
        try:
            self.runtimes.catch_up(self.runtime, items[0].missed)  # duplicates build nothing
        except BaseException:
            self.runtimes.forget(self.fleet_id)


class GroupCommit:
    """The write path of a service: queues, writers and the commit thread.

    Parameters
    ----------
    log
        The event log written to.
    runtimes
        The fleets' runtimes and locks.
    """

    def __init__(self, log: EventLog, runtimes: FleetRuntimes) -> None:
        self.log = log
        self.runtimes = runtimes
        self._queue: deque[QueuedWrite] = deque()
        self._queue_cond = threading.Condition()
        self._writer: threading.Thread | None = None
        self._closed = False
        # the event loop's writer (see the module's docstring)
        self._loop_queue: deque[QueuedWrite] = deque()
        self._loop_drain: asyncio.Task[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._committer: Committer | None = None
        self._watched: set[Future[Any]] = set()
        self._hold_none = False

    @property
    def committer(self) -> Committer | None:
        """The thread that commits the event loop's transactions, once one ran."""
        return self._committer

    def submit(
        self,
        fleet_id: str,
        compute: Compute,
        *,
        idempotency_key: str | None = None,
        digest: str | None = None,
        size: int = 1,
        loop: asyncio.AbstractEventLoop | None = None,
    ) -> PendingAnswer:
        """Queue ``compute(runtime) -> [NewEvent]`` for the next group commit.

        Parameters
        ----------
        fleet_id
            The fleet.
        compute
            Applies the request to the runtime (under the fleet's lock) and
            returns its events; a :class:`RoutingSvcError` it raises before
            changing the runtime fails this request alone.
        idempotency_key, digest
            The request's idempotency key and request hash.
        size
            How many events the request will write, counted against
            :data:`~routing_svc.service.write_path.pending.GROUP_CAP`.
        loop
            The running event loop, for a coroutine calling on its thread: on
            SQLite the loop then stages the request's group itself (see the
            module's docstring). ``None``: the writer thread writes it.

        Returns
        -------
        concurrent.futures.Future or asyncio.Future
            A future of ``loop`` when one is given, else a concurrent one.
            Resolves, only after the transaction committed, to each event's
            result JSON and the ``seq`` of the request's last event (the
            fleet's version if it wrote none), or to the request's error.
        """
        mine = QueuedWrite(fleet_id, compute, idempotency_key, digest, size, loop)
        if loop is not None and self.log.dialect == "sqlite":
            if self._closed:
                raise StorageError("the fleet service is shut down")
            self._loop_queue.append(mine)
            self._loop = loop
            self._restart_loop_drain()
            return mine.future
        with self._queue_cond:
            if self._closed:
                raise StorageError("the fleet service is shut down")
            self._queue.append(mine)
            if self._writer is None:
                self._writer = threading.Thread(
                    target=self._write_loop, name="routing-svc-writer", daemon=True
                )
                self._writer.start()
            self._queue_cond.notify()
        return mine.future

    @contextmanager
    def together(self) -> Iterator[None]:
        """Hold the writer thread: what is submitted (without a loop) inside the block
        is taken as one batch when it ends, as far as
        :data:`~routing_svc.service.write_path.pending.GROUP_CAP` allows."""
        with self._queue_cond:
            yield

    def close(self) -> None:
        """Commit what the writer thread has queued, then stop it.

        Await :meth:`drain` first on the event loop that wrote: what is still
        in its queue then fails with :class:`StorageError`.
        """
        with self._queue_cond:
            self._closed = True
            self._queue_cond.notify_all()
            writer = self._writer
        if writer is not None and writer is not threading.current_thread():
            writer.join()
        while self._loop_queue:
            self._loop_queue.popleft().fail(StorageError("the fleet service is shut down"))
        if self._committer is not None:
            self._committer.close()

    async def settled(self, answer: PendingAnswer, *, deadline: float | None) -> Answer:
        """Wait for the answer of a request :meth:`submit` queued, until ``deadline``.

        Parameters
        ----------
        answer
            What :meth:`submit` returned.
        deadline
            Event-loop time; ``None``: wait as long as it takes.

        Raises
        ------
        StorageTimeout
            The deadline passed before a writer took the request: it was withdrawn
            and will never be written.
        CommitOutcomeUnknown
            The deadline passed while its transaction ran: it may commit. A retry
            with the same idempotency key settles it.
        """
        waiter = answer if isinstance(answer, asyncio.Future) else asyncio.wrap_future(answer)
        if deadline is None:
            return await waiter
        bound = asyncio.timeout_at(deadline)
        try:
            async with bound:
                return await waiter
        except TimeoutError:
            if not bound.expired():
                raise
        if self.withdraw(answer):
            raise StorageTimeout("a write waited for the store past its deadline; withdrawn")
        raise CommitOutcomeUnknown("a write's deadline passed while its transaction ran")

    def withdraw(self, answer: PendingAnswer) -> bool:
        """Take back a queued request that no writer has taken yet.

        Returns
        -------
        bool
            ``True``: it was still queued and will never be written; ``False``: a
            writer has it (or answered it already). Called on the event loop's thread.
        """
        with self._queue_cond:
            for queue in (self._queue, self._loop_queue):
                for pending in queue:
                    if pending.future is answer:
                        queue.remove(pending)
                        pending.settled = True
                        return True
        return False

    async def drain(self) -> None:
        """Wait until the event loop's writer has committed everything queued to it (its
        errors went to the requests' answers), fleets held for their consolidation
        included."""
        self._hold_none = True
        try:
            self._restart_loop_drain()
            while self._loop_drain is not None:
                await asyncio.wait({self._loop_drain})
                self._restart_loop_drain()
        finally:
            self._hold_none = False

    # -- fleets held for their consolidation -----------------------------------------

    def _holds(self, fleet_id: str, events_ahead: int) -> bool:
        """Whether the fleet's queued writes wait for its consolidation's solve
        (:meth:`FleetRuntimes.consolidation_wait`); its end wakes the writers."""
        if self._closed or self._hold_none:
            return False
        answer = self.runtimes.consolidation_wait(fleet_id, events_ahead)
        if answer is None:
            return False
        if answer not in self._watched:
            self._watched.add(answer)
            answer.add_done_callback(self._wake)
        return True

    def _wake(self, answer: Future[Any]) -> None:
        """A solve ended: the writers take the writes held for it."""
        self._watched.discard(answer)
        with self._queue_cond:
            self._queue_cond.notify()
        loop = self._loop
        if loop is not None and self._loop_queue:
            with suppress(RuntimeError):  # a closed loop writes no more
                loop.call_soon_threadsafe(self._restart_loop_drain)

    def _restart_loop_drain(self) -> None:
        """Start the event loop's writer unless it runs or has nothing queued (called on
        the loop's thread)."""
        if self._loop_queue and self._loop_drain is None and self._loop is not None:
            self._loop_drain = self._loop.create_task(self._drain_on_loop())

    # -- the event loop's writer --------------------------------------------------

    async def _drain_on_loop(self) -> None:
        """Commit the event loop's queue, group after group, until it is empty."""
        try:
            while self._loop_queue:
                batch = take_batch(self._loop_queue, self._holds)
                if not batch:  # every fleet queued here waits for its consolidation
                    asyncio.get_running_loop().call_later(HELD_RECHECK_S, self._restart_loop_drain)
                    break
                try:
                    await self._commit_on_loop(batch)
                except BaseException as exc:  # never leave a caller waiting
                    fail_unfinished(batch, exc)
                    if not isinstance(exc, Exception):
                        raise
        finally:
            self._loop_drain = None

    async def _commit_on_loop(self, batch: list[QueuedWrite]) -> None:
        """Stage the batch's transaction here, commit it on the committer thread.

        Staging never waits: the fleets' locks and the database's write lock
        are only tried. If one is taken, or a fleet is not in memory, or a fleet's
        targets could wait for a solve, or the transaction fails, the batch goes to a
        worker thread as a whole
        (:meth:`_commit`), after any runtime the staging changed was dropped.
        """
        loop = asyncio.get_running_loop()
        by_fleet = _by_fleet(batch)
        held: list[threading.Lock] = []
        shares: list[_FleetShare] = []
        committed = False
        try:
            ready = True
            for fleet_id in sorted(by_fleet):
                lock = self.runtimes.lock_of(fleet_id)
                if not self.runtimes.is_cached(fleet_id) or not lock.acquire(blocking=False):
                    ready = False
                    break
                held.append(lock)
                if self.runtimes.solves_within(fleet_id, sum(p.size for p in by_fleet[fleet_id])):
                    ready = False  # its wait must not hold the event loop
                    break
            if ready:
                opened = None
                try:
                    shares = [
                        _FleetShare(self.runtimes, fid, by_fleet[fid]) for fid in sorted(by_fleet)
                    ]
                    opened = self.log.try_append_groups_uncommitted([s.request() for s in shares])
                    if opened is not None:
                        await self._commit_beside_loop(loop, opened.commit)
                        committed = True
                except BaseException as exc:
                    # computed (perhaps in part) but not durable: rebuild from the log
                    for share in shares:
                        self.runtimes.forget(share.fleet_id)
                    if not isinstance(exc, Exception):
                        # cancelled while the commit may be running: its outcome is
                        # unknown, so nothing is tried again (a retry with an
                        # idempotency key finds out)
                        raise
                if committed:
                    assert opened is not None
                    COMMITS.labels("event_loop").inc()
                    for share, items in zip(shares, opened.items, strict=True):
                        share.settle(items)
        finally:
            for lock in held:
                lock.release()
        if not committed:
            rest = [p for p in batch if not p.settled]
            if rest:
                await loop.run_in_executor(None, self._commit, rest)

    async def _commit_beside_loop(
        self, loop: asyncio.AbstractEventLoop, commit: Callable[[], None]
    ) -> None:
        """Run ``commit`` on the committer thread (:meth:`Committer.hand_over`: the loop
        blocks until the thread has started it, at most
        :data:`~routing_svc.service.write_path.committer.COMMIT_HANDOFF_WAIT`), then
        await its end without blocking the loop."""
        if self._committer is None:
            self._committer = Committer("routing-svc-commit")
        await self._committer.hand_over(loop, commit)

    # -- the writer thread --------------------------------------------------------

    def _write_loop(self) -> None:
        while True:
            with self._queue_cond:
                while True:
                    batch = take_batch(self._queue, self._holds) if self._queue else []
                    if batch or (self._closed and not self._queue):
                        break
                    self._queue_cond.wait(HELD_RECHECK_S if self._queue else None)
                if not batch:
                    return
            try:
                self._commit(batch)
            except BaseException as exc:  # never leave a caller waiting
                fail_unfinished(batch, exc)

    def _commit(self, batch: list[QueuedWrite]) -> None:
        """Commit a batch: all fleets in one transaction, else fleet by fleet."""
        by_fleet = _by_fleet(batch)
        if len(by_fleet) > 1 and self._commit_together(by_fleet):
            return
        for fleet_id, group in by_fleet.items():
            while group:
                group = self._commit_group(fleet_id, group)

    def _commit_together(self, by_fleet: dict[str, list[QueuedWrite]]) -> bool:
        """One transaction for several fleets; ``False`` (nothing answered, runtimes of
        the fleets involved dropped) if it failed."""
        with ExitStack() as locks:
            shares: list[_FleetShare] = []
            for fleet_id in sorted(by_fleet):
                locks.enter_context(self.runtimes.lock_of(fleet_id))
                try:
                    shares.append(_FleetShare(self.runtimes, fleet_id, by_fleet[fleet_id]))
                except BaseException:
                    self.runtimes.forget(fleet_id)
                    return False
            try:
                results = self.log.append_groups([share.request() for share in shares])
            except CommitOutcomeUnknown as exc:
                # it may have committed: trying again fleet by fleet could apply
                # requests without a key twice; a keyed retry settles each one
                for share in shares:
                    self.runtimes.forget(share.fleet_id)
                    fail_unfinished(share.group, exc)
                return True
            except BaseException:
                for share in shares:
                    self.runtimes.forget(share.fleet_id)
                    for pending in share.diverged:
                        share.group.remove(pending)  # its future holds its error
                return False
            COMMITS.labels("thread").inc()
            for share, items in zip(shares, results, strict=True):
                share.settle(items)
            return True

    def _commit_group(self, fleet_id: str, group: list[QueuedWrite]) -> list[QueuedWrite]:
        """One fleet's requests in one transaction; answer them.

        Returns
        -------
        list[QueuedWrite]
            The requests to commit again (nothing was written for them): after
            a request failed having changed the runtime, which is then dropped.
        """
        with self.runtimes.lock_of(fleet_id):
            try:
                share = _FleetShare(self.runtimes, fleet_id, group)
            except BaseException as exc:
                for pending in group:
                    pending.fail(exc)
                return []
            try:
                (items,) = self.log.append_groups([share.request()])
            except _Diverged:
                self.runtimes.forget(fleet_id)
                return [p for p in group if p not in share.diverged]
            except BaseException as exc:
                self.runtimes.forget(fleet_id)
                for pending in group:
                    pending.fail(exc)
                return []
            COMMITS.labels("thread").inc()
            share.settle(items)
            return []


def _by_fleet(batch: list[QueuedWrite]) -> dict[str, list[QueuedWrite]]:
    """The batch's requests by fleet, in order (fleets in order of first appearance)."""
    by_fleet: dict[str, list[QueuedWrite]] = {}
    for pending in batch:
        by_fleet.setdefault(pending.fleet_id, []).append(pending)
    return by_fleet
