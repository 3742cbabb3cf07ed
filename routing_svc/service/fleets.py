"""Fleet operations over the event log: the domain side of the REST API.

Every write is committed in groups (group commit): a write request joins a
queue and gets a future; a writer takes everything queued (up to
:data:`GROUP_CAP` events), and commits the requests of all fleets in it in
one transaction (:meth:`EventLog.append_groups`), so one ``fsync``
acknowledges them all.

There are two writers. Requests made on an event loop's thread (the REST
API's target routes) are written *by that event loop* on SQLite: it computes
the group and stages its transaction itself, without waiting for any lock,
and only the commit (the ``fsync``) runs on a worker thread, while the loop
goes on serving requests. The targets' Python work thus stays on one thread
instead of passing the interpreter lock back and forth with a writer thread
for every target. The loop hands the interpreter lock to the committer for
the few microseconds it needs to start the commit
(:mod:`~routing_svc.service.committer`): CPython would otherwise let it run
only when the loop next idles, after the loop parsed the next requests, so the
disk's wait would follow that work instead of overlapping it. When staging is
not possible at once (another thread or process holds the write lock, a
fleet's lock is taken, a fleet is not in memory), the group goes to a worker
thread as a whole. Every other request (from worker threads, and all of them
on PostgreSQL, whose statements wait on the network) joins the queue of the
writer thread.

Under each fleet's lock the cached :class:`FleetRuntime` first replays the
events other workers (or hosts) wrote since it last looked, then computes
each request's events in queue order; a request that fails with a domain
error fails alone. Every future is resolved only after the transaction
committed. If the shared transaction fails, each fleet's requests are
committed on their own, so one fleet's trouble cannot fail another's
requests; a cache that may have diverged (an append that failed after
computing) is dropped and rebuilt from the log.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import threading
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from prometheus_client import Counter, Histogram

from routing_svc.errors import (
    CommitOutcomeUnknown,
    Conflict,
    RoutingSvcError,
    StorageError,
    StorageTimeout,
    UnknownFleet,
    UnknownNetwork,
)
from routing_svc.service.canonical import dumps
from routing_svc.service.committer import Committer
from routing_svc.service.creation import build_created_payload
from routing_svc.service.networks import NetworkEntry, NetworkRegistry
from routing_svc.service.runtime import FleetRuntime, same_snapshot
from routing_svc.service.schemas import FleetSpec, TargetSpec, VehicleStateChange
from routing_svc.service.vehicle_states import resolve_changes
from routing_svc.store import EventLog, EventRecord, FleetGroup, GroupItem, NewEvent
from routing_svc.types import NetPosition

SNAPSHOT_EVERY = 64
"""A snapshot of the state is stored whenever the version crosses a multiple of this."""
GROUP_CAP = 256
"""At most this many targets (or other events) are committed in one group."""

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

Compute = Callable[[FleetRuntime], list[NewEvent]]
"""``compute(runtime) -> new events``: applies one request to the runtime."""


class _Diverged(Exception):
    """A request failed after changing the runtime: nothing may be written."""


Answer = tuple[list[str], int]
"""Each event's result JSON, and the ``seq`` of the request's last event."""

Outcome = Future[Answer] | asyncio.Future[Answer]
"""The future of a queued request: the event loop's own for a request staged on it."""


class _Pending:
    """One write request waiting in the service's queue.

    Its future is a :class:`concurrent.futures.Future`, or, for a request made
    on an event loop (``loop``), a future of that loop: it is answered there
    without a trip through another thread. Either way it is answered exactly
    once, by :meth:`resolve` or :meth:`fail`, from any thread.
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
        self.future: Outcome
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


def _set_future(future: Outcome, answer: Answer | None, error: BaseException | None) -> None:
    """Set the outcome of a request's future; a loop's future that its waiter cancelled
    (the client went away) takes none."""
    if future.cancelled():
        return
    if error is not None:
        future.set_exception(error)
    else:
        future.set_result(answer)  # type: ignore[arg-type]


class _FleetJob:
    """One fleet's share of a commit: its runtime, requests and callbacks."""

    def __init__(self, service: FleetService, fleet_id: str, group: list[_Pending]) -> None:
        self.service = service
        self.fleet_id = fleet_id
        self.group = group
        self.runtime = service._runtime(fleet_id, fresh=False)
        self.before = self.runtime.version
        self.diverged: list[_Pending] = []

    def build(
        self, missed: list[EventRecord], fresh: list[int]
    ) -> list[list[NewEvent] | RoutingSvcError]:
        runtime = self.runtime
        self.service._replay(runtime, missed)
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
        due = version // SNAPSHOT_EVERY != self.before // SNAPSHOT_EVERY
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
        """Resolve every request's future from its :class:`GroupItem`."""
        COMMIT_GROUP_SIZE.observe(len(self.group))
        for pending, item in zip(self.group, items, strict=True):
            if item.error is not None:
                pending.fail(item.error)
            else:
                last = item.events[-1].seq if item.events else item.version
                pending.resolve(([e.result_json or "{}" for e in item.events], last))
        try:
            self.service._replay(self.runtime, items[0].missed)  # duplicates build nothing
        except BaseException:
            self.service._cache.pop(self.fleet_id, None)


def request_hash(body: Any) -> str:
    """A digest of a request body, stored with its idempotency key."""
    return hashlib.sha256(dumps(body).encode()).hexdigest()


class FleetService:
    """Fleets, targets and travel times, durable in an :class:`EventLog`."""

    def __init__(self, log: EventLog, networks: NetworkRegistry, *, recent_window: int) -> None:
        self.log = log
        self.networks = networks
        self.recent_window = recent_window
        self._cache: dict[str, FleetRuntime] = {}
        self._locks: dict[str, threading.Lock] = {}
        self._locks_guard = threading.Lock()
        self._queue: deque[_Pending] = deque()
        self._queue_cond = threading.Condition()
        self._writer: threading.Thread | None = None
        self._closed = False
        # the event loop's writer (see the module's docstring)
        self._loop_queue: deque[_Pending] = deque()
        self._loop_drain: asyncio.Task[None] | None = None
        self._committer: Committer | None = None
        self._levels_seen: dict[str, dict[str, Any]] = {}

    # -- plumbing ---------------------------------------------------------------

    def _lock_of(self, fleet_id: str) -> threading.Lock:
        with self._locks_guard:
            return self._locks.setdefault(fleet_id, threading.Lock())

    @contextmanager
    def _locked(self, fleet_id: str) -> Iterator[None]:
        with self._lock_of(fleet_id):
            yield

    def network(self, network_id: str) -> NetworkEntry:
        """A loaded network; one that another instance registered is loaded from its
        stored path when this host can read it (a shared ``--data-dir``)."""
        if network_id not in self.networks:
            record = self.log.get_network(network_id)
            path = Path(record.path)
            if not path.is_file():
                raise UnknownNetwork(
                    f"network {network_id!r} is registered, but its file {record.path!r} "
                    "is not readable on this instance (share --data-dir between instances)"
                )
            self.networks.load(record.id, path, name=record.name)
        return self.networks.get(network_id)

    def _load(self, fleet_id: str) -> FleetRuntime:
        """Build the runtime from the snapshot and the events after it."""
        record = self.log.get_fleet(fleet_id)
        entry = self.network(record.network_id)
        first = self.log.events(fleet_id, after=0, limit=1)[0]
        runtime = FleetRuntime(
            fleet_id, entry, json.loads(first.payload_json), recent_window=self.recent_window
        )
        if (
            record.state_json is not None
            and record.snapshot_version is not None
            and not runtime.restore(record.state_json)
        ):  # a snapshot older than service levels: replay the fleet from its start
            runtime = FleetRuntime(
                fleet_id, entry, json.loads(first.payload_json), recent_window=self.recent_window
            )
        self._replay(runtime, self.log.events_since(fleet_id, runtime.version))
        return runtime

    @staticmethod
    def _replay(runtime: FleetRuntime, events: Sequence[EventRecord]) -> None:
        for event in events:
            if event.seq > runtime.version:
                runtime.replay(event.seq, event.kind, event.payload_json, event.result_json)

    def _runtime(self, fleet_id: str, *, fresh: bool = True) -> FleetRuntime:
        """The cached runtime, caught up with the log when ``fresh``."""
        runtime = self._cache.get(fleet_id)
        if runtime is None:
            runtime = self._load(fleet_id)
            self._cache[fleet_id] = runtime
        elif fresh:
            record = self.log.get_fleet(fleet_id)
            if record.version > runtime.version:
                self._replay(runtime, self.log.events_since(fleet_id, runtime.version))
        if runtime.deleted:
            raise UnknownFleet(f"no fleet {fleet_id!r}")
        return runtime

    def is_cached(self, fleet_id: str) -> bool:
        """Whether the fleet's runtime is in memory (a write then needs no database read
        before it joins the queue)."""
        runtime = self._cache.get(fleet_id)
        return runtime is not None and not runtime.deleted

    # -- the writer -------------------------------------------------------------

    def submit(
        self,
        fleet_id: str,
        compute: Compute,
        *,
        idempotency_key: str | None = None,
        digest: str | None = None,
        size: int = 1,
        loop: asyncio.AbstractEventLoop | None = None,
    ) -> Outcome:
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
            :data:`GROUP_CAP`.
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
        mine = _Pending(fleet_id, compute, idempotency_key, digest, size, loop)
        if loop is not None and self.log.dialect == "sqlite":
            if self._closed:
                raise StorageError("the fleet service is shut down")
            self._loop_queue.append(mine)
            if self._loop_drain is None:
                self._loop_drain = loop.create_task(self._drain_on_loop())
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

    async def settled(self, future: Outcome, *, deadline: float | None) -> Answer:
        """Wait for the answer of a request :meth:`submit` queued, until ``deadline``.

        Parameters
        ----------
        future
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
        waiter = future if isinstance(future, asyncio.Future) else asyncio.wrap_future(future)
        if deadline is None:
            return await waiter
        bound = asyncio.timeout_at(deadline)
        try:
            async with bound:
                return await waiter
        except TimeoutError:
            if not bound.expired():
                raise
        if self.withdraw(future):
            raise StorageTimeout("a write waited for the store past its deadline; withdrawn")
        raise CommitOutcomeUnknown("a write's deadline passed while its transaction ran")

    def withdraw(self, future: Outcome) -> bool:
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
                    if pending.future is future:
                        queue.remove(pending)
                        pending.settled = True
                        return True
        return False

    async def drain(self) -> None:
        """Wait until the event loop's writer has committed everything queued to it (its
        errors went to the requests' futures)."""
        while self._loop_drain is not None:
            await asyncio.wait({self._loop_drain})

    # -- the event loop's writer --------------------------------------------------

    async def _drain_on_loop(self) -> None:
        """Commit the event loop's queue, group after group, until it is empty."""
        try:
            while self._loop_queue:
                batch = _take_batch(self._loop_queue)
                try:
                    await self._commit_on_loop(batch)
                except BaseException as exc:  # never leave a caller waiting
                    _fail_unfinished(batch, exc)
                    if not isinstance(exc, Exception):
                        raise
        finally:
            self._loop_drain = None

    async def _commit_on_loop(self, batch: list[_Pending]) -> None:
        """Stage the batch's transaction here, commit it on the committer thread.

        Staging never waits: the fleets' locks and the database's write lock
        are only tried. If one is taken, or a fleet is not in memory, or the
        transaction fails, the batch goes to a worker thread as a whole
        (:meth:`_commit`), after any cache the staging changed was dropped.
        """
        loop = asyncio.get_running_loop()
        by_fleet: dict[str, list[_Pending]] = {}
        for pending in batch:
            by_fleet.setdefault(pending.fleet_id, []).append(pending)
        held: list[threading.Lock] = []
        jobs: list[_FleetJob] = []
        committed = False
        try:
            ready = True
            for fleet_id in sorted(by_fleet):
                lock = self._lock_of(fleet_id)
                if not self.is_cached(fleet_id) or not lock.acquire(blocking=False):
                    ready = False
                    break
                held.append(lock)
            if ready:
                opened = None
                try:
                    jobs = [_FleetJob(self, fid, by_fleet[fid]) for fid in sorted(by_fleet)]
                    opened = self.log.try_append_groups_uncommitted([job.request() for job in jobs])
                    if opened is not None:
                        await self._commit_beside_loop(loop, opened.commit)
                        committed = True
                except BaseException as exc:
                    # computed (perhaps in part) but not durable: rebuild from the log
                    for job in jobs:
                        self._cache.pop(job.fleet_id, None)
                    if not isinstance(exc, Exception):
                        # cancelled while the commit may be running: its outcome is
                        # unknown, so nothing is tried again (a retry with an
                        # idempotency key finds out)
                        raise
                if committed:
                    assert opened is not None
                    COMMITS.labels("event_loop").inc()
                    for job, items in zip(jobs, opened.items, strict=True):
                        job.settle(items)
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
        :data:`~routing_svc.service.committer.COMMIT_HANDOFF_WAIT`), then await its end
        without blocking the loop."""
        if self._committer is None:
            self._committer = Committer("routing-svc-commit")
        await self._committer.hand_over(loop, commit)

    def _write_loop(self) -> None:
        while True:
            with self._queue_cond:
                while not self._queue and not self._closed:
                    self._queue_cond.wait()
                if not self._queue:
                    return
                batch = _take_batch(self._queue)
            try:
                self._commit(batch)
            except BaseException as exc:  # never leave a caller waiting
                _fail_unfinished(batch, exc)

    def _commit(self, batch: list[_Pending]) -> None:
        """Commit a batch: all fleets in one transaction, else fleet by fleet."""
        by_fleet: dict[str, list[_Pending]] = {}
        for pending in batch:
            by_fleet.setdefault(pending.fleet_id, []).append(pending)
        if len(by_fleet) > 1 and self._commit_together(by_fleet):
            return
        for fleet_id, group in by_fleet.items():
            while group:
                group = self._commit_group(fleet_id, group)

    def _commit_together(self, by_fleet: dict[str, list[_Pending]]) -> bool:
        """One transaction for several fleets; ``False`` (nothing resolved, caches of
        the fleets involved dropped) if it failed."""
        with ExitStack() as locks:
            jobs: list[_FleetJob] = []
            for fleet_id in sorted(by_fleet):
                locks.enter_context(self._locked(fleet_id))
                try:
                    jobs.append(_FleetJob(self, fleet_id, by_fleet[fleet_id]))
                except BaseException:
                    self._cache.pop(fleet_id, None)
                    return False
            try:
                results = self.log.append_groups([job.request() for job in jobs])
            except CommitOutcomeUnknown as exc:
                # it may have committed: trying again fleet by fleet could apply
                # requests without a key twice; a keyed retry settles each one
                for job in jobs:
                    self._cache.pop(job.fleet_id, None)
                    _fail_unfinished(job.group, exc)
                return True
            except BaseException:
                for job in jobs:
                    self._cache.pop(job.fleet_id, None)
                    for pending in job.diverged:
                        job.group.remove(pending)  # its future holds its error
                return False
            COMMITS.labels("thread").inc()
            for job, items in zip(jobs, results, strict=True):
                job.settle(items)
            return True

    def _commit_group(self, fleet_id: str, group: list[_Pending]) -> list[_Pending]:
        """One fleet's requests in one transaction; resolve their futures.

        Returns
        -------
        list[_Pending]
            The requests to commit again (nothing was written for them): after
            a request failed having changed the runtime, which is then dropped.
        """
        with self._locked(fleet_id):
            try:
                job = _FleetJob(self, fleet_id, group)
            except BaseException as exc:
                for pending in group:
                    pending.fail(exc)
                return []
            try:
                (items,) = self.log.append_groups([job.request()])
            except _Diverged:
                self._cache.pop(fleet_id, None)
                return [p for p in group if p not in job.diverged]
            except BaseException as exc:
                self._cache.pop(fleet_id, None)
                for pending in group:
                    pending.fail(exc)
                return []
            COMMITS.labels("thread").inc()
            job.settle(items)
            return []

    # -- fleets -----------------------------------------------------------------

    def create_fleet(self, spec: FleetSpec) -> dict[str, Any]:
        entry = self.network(spec.network)
        created = build_created_payload(spec, entry)
        runtime = FleetRuntime(spec.id, entry, created, recent_window=self.recent_window)
        self.log.create_fleet(spec.id, entry.id, dumps(created["config"]), dumps(created))
        with self._locked(spec.id):
            self._cache[spec.id] = runtime
        return runtime.describe()

    def get_fleet(self, fleet_id: str) -> dict[str, Any]:
        with self._locked(fleet_id):
            return self._runtime(fleet_id).describe()

    def list_fleets(self) -> list[dict[str, Any]]:
        out = []
        for record in self.log.list_fleets():
            try:
                out.append(self.get_fleet(record.id))
            except UnknownFleet:
                continue
        return out

    def delete_fleet(self, fleet_id: str) -> None:
        with self._locked(fleet_id):
            self._runtime(fleet_id)
            self.log.delete_fleet(fleet_id)
            self._cache.pop(fleet_id, None)

    def metrics(self, fleet_id: str) -> dict[str, Any]:
        with self._locked(fleet_id):
            return self._runtime(fleet_id).metrics()

    def cached_service_levels(self) -> list[tuple[str, dict[str, Any]]]:
        """``(fleet id, service levels)`` of every fleet in memory (no database read).

        A fleet's lock is only tried, never waited for: the event loop may hold it
        across an ``await`` (:meth:`_commit_on_loop`), and a scrape runs on that loop.
        A fleet whose lock is taken reports what it reported last.
        """
        out = []
        for fleet_id in sorted(self._cache):
            lock = self._lock_of(fleet_id)
            if lock.acquire(blocking=False):
                try:
                    runtime = self._cache.get(fleet_id)
                    if runtime is None or runtime.deleted:
                        self._levels_seen.pop(fleet_id, None)
                    else:
                        self._levels_seen[fleet_id] = runtime.levels.report()
                finally:
                    lock.release()
            if fleet_id in self._levels_seen:
                out.append((fleet_id, self._levels_seen[fleet_id]))
        return out

    def events(self, fleet_id: str, *, after: int, limit: int) -> list[dict[str, Any]]:
        return [
            {
                "seq": e.seq,
                "kind": e.kind,
                "payload": json.loads(e.payload_json),
                "result": None if e.result_json is None else json.loads(e.result_json),
                "created_at": e.created_at.isoformat(),
            }
            for e in self.log.events(fleet_id, after=after, limit=limit)
        ]

    # -- targets ----------------------------------------------------------------

    def _resolve_targets(
        self, fleet_id: str, targets: Sequence[TargetSpec]
    ) -> list[tuple[NetPosition, list[str] | None]]:
        cached = self._cache.get(fleet_id)  # a fleet's network never changes: no lock
        if cached is not None and not cached.deleted:
            entry = cached.entry
        else:
            with self._locked(fleet_id):
                entry = self._runtime(fleet_id, fresh=False).entry
        return [
            (entry.resolve(t.position), list(t.requires) if t.requires else None) for t in targets
        ]

    def submit_targets(
        self,
        fleet_id: str,
        targets: Sequence[TargetSpec],
        *,
        idempotency_key: str | None = None,
        body: Any = None,
        loop: asyncio.AbstractEventLoop | None = None,
    ) -> Outcome:
        """Queue targets to be applied in order in one transaction (see :meth:`submit`,
        also for ``loop``).

        Positions are resolved first, so a bad position fails here and queues nothing.
        """
        resolved = self._resolve_targets(fleet_id, targets)

        def compute(runtime: FleetRuntime) -> list[NewEvent]:
            out = []
            for position, requires in resolved:
                payload, result = runtime.apply_target(position, requires)
                out.append(NewEvent("target", payload, result))
            return out

        digest = request_hash(body) if idempotency_key is not None else None
        return self.submit(
            fleet_id,
            compute,
            idempotency_key=idempotency_key,
            digest=digest,
            size=len(resolved),
            loop=loop,
        )

    def post_targets(
        self,
        fleet_id: str,
        targets: Sequence[TargetSpec],
        *,
        idempotency_key: str | None = None,
        body: Any = None,
    ) -> tuple[list[str], int]:
        """Apply targets in order in one transaction; return each result's JSON text."""
        return self.submit_targets(
            fleet_id, targets, idempotency_key=idempotency_key, body=body
        ).result()

    def assign(self, fleet_id: str, target: TargetSpec) -> dict[str, Any]:
        """Who would go now (``dispatch``) and whose reference would move (``moved``,
        from the closest references ``served_by``); changes nothing."""
        ((position, requires),) = self._resolve_targets(fleet_id, [target])
        with self._locked(fleet_id):
            runtime = self._runtime(fleet_id)
            d = runtime.fleet.assign(position, requires)
            assert d.sent is not None
            return {
                "version": runtime.version,
                "target": runtime.entry.describe(position),
                "requires": requires,
                "dispatch": d.sent.to_dict(),
                "served_by": list(d.served_by),
                "times": list(d.times),
                "moved": d.moved,
                "cost": d.cost,
                "objective": d.objective,
            }

    def submit_vehicle_states(
        self,
        fleet_id: str,
        changes: Sequence[VehicleStateChange],
        *,
        idempotency_key: str | None = None,
        body: Any = None,
    ) -> Outcome:
        """Queue vehicles' new live states, one ``vehicle_state`` event, all or none.

        Positions are resolved first, so a position off the network fails here
        and queues nothing; an unknown vehicle or a timestamp that goes back in
        time fails the request when it is applied, before anything changed.
        """
        with self._locked(fleet_id):
            entry = self._runtime(fleet_id, fresh=False).entry
        resolved = [(c, None if c.position is None else entry.resolve(c.position)) for c in changes]

        def compute(runtime: FleetRuntime) -> list[NewEvent]:
            payload, result = runtime.apply_vehicle_states(resolve_changes(runtime, resolved))
            return [NewEvent("vehicle_state", payload, result)]

        digest = request_hash(body) if idempotency_key is not None else None
        return self.submit(fleet_id, compute, idempotency_key=idempotency_key, digest=digest)

    def put_vehicle_states(
        self,
        fleet_id: str,
        changes: Sequence[VehicleStateChange],
        *,
        idempotency_key: str | None = None,
        body: Any = None,
    ) -> dict[str, Any]:
        """Apply :meth:`submit_vehicle_states` and wait for its commit; the event's result."""
        results, _ = self.submit_vehicle_states(
            fleet_id, changes, idempotency_key=idempotency_key, body=body
        ).result()
        data: dict[str, Any] = json.loads(results[0])
        return data

    def put_travel_times(self, fleet_id: str, times: dict[str, float]) -> dict[str, Any]:
        with self._locked(fleet_id):
            runtime = self._runtime(fleet_id, fresh=False)
            if runtime.cost_kind != "time":
                raise Conflict(
                    "this fleet uses length costs; travel times apply to cost='time' fleets"
                )
            runtime.base_space.with_travel_times(times)  # validates before anything is written

        def compute(runtime: FleetRuntime) -> list[NewEvent]:
            payload, result = runtime.apply_travel_times(times)
            return [NewEvent("weights_updated", payload, result)]

        results, _ = self.submit(fleet_id, compute).result()
        data: dict[str, Any] = json.loads(results[0])
        return data

    # -- replay -----------------------------------------------------------------

    def verify(self, fleet_id: str) -> dict[str, Any]:
        """Rebuild the fleet from its whole log and compare with the stored snapshot."""
        from routing_svc.errors import ReplayMismatch

        record = self.log.get_fleet(fleet_id, include_deleted=True)
        entry = self.network(record.network_id)
        events = self.log.events_since(fleet_id, 0)
        runtime = FleetRuntime(
            fleet_id, entry, json.loads(events[0].payload_json), recent_window=self.recent_window
        )
        identical = None
        at = record.snapshot_version
        if record.state_json is not None and at is not None:
            self._replay(runtime, [e for e in events[1:] if e.seq <= at])
            identical = same_snapshot(runtime.snapshot_json(), record.state_json)
            if not identical:
                raise ReplayMismatch(
                    f"fleet {fleet_id!r}: the replayed state at version {at} differs from the "
                    "stored snapshot"
                )
        self._replay(runtime, events[1:])
        if runtime.version != record.version:
            raise ReplayMismatch(
                f"replay reached version {runtime.version}, stored {record.version}"
            )
        return {
            "fleet": fleet_id,
            "version": runtime.version,
            "events": len(events),
            "snapshot_version": at,
            "snapshot_identical": identical,
            "state_sha256": hashlib.sha256(runtime.snapshot_json().encode()).hexdigest(),
        }


def _take_batch(queue: deque[_Pending]) -> list[_Pending]:
    """Take the next batch from a non-empty ``queue``: its oldest requests, up to
    :data:`GROUP_CAP` events (at least one request)."""
    batch = [queue.popleft()]
    total = batch[0].size
    while queue and total + queue[0].size <= GROUP_CAP:
        total += queue[0].size
        batch.append(queue.popleft())
    return batch


def _fail_unfinished(batch: list[_Pending], error: BaseException) -> None:
    """Fail every request of ``batch`` that has no answer yet."""
    for pending in batch:
        pending.fail(error)
