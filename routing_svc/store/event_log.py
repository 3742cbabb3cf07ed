"""The event log: each fleet as a numbered stream of JSON events.

A fleet's state is the replay of its events; the ``fleets`` row keeps its
version (the last event's ``seq``) and an optional snapshot so restarts are
fast. :meth:`EventLog.append` is the one way to add events: in one transaction
it locks the fleet row (``SELECT ... FOR UPDATE`` on PostgreSQL, the database
write lock taken by ``BEGIN IMMEDIATE`` on SQLite), answers a retried
idempotency key from the log, hands the events the caller has not seen yet to
its ``build`` callback, and writes what ``build`` returns with contiguous
numbers. Workers in several processes or on several hosts therefore apply
events in one order, each replaying what it missed before computing the next.
A call returns only after its transaction has committed.

Deleting a fleet is a *soft* delete: the row is marked ``deleted`` and a
``fleet_deleted`` event closes the stream. The log stays readable as an audit
trail, and the id is never reused, so a worker holding a stale cache of the old
fleet cannot mistake a new fleet for it.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, nullcontext, suppress
from dataclasses import dataclass
from datetime import datetime
from types import TracebackType
from typing import Any, Self

import sqlalchemy as sa
from sqlalchemy.engine import Connection, Engine

from routing_svc.errors import (
    Conflict,
    InvalidInput,
    RoutingSvcError,
    StorageError,
    UnknownFleet,
    UnknownNetwork,
)
from routing_svc.store import engine as store_engine
from routing_svc.store import queries as q
from routing_svc.store.checkpoint import WalCheckpointer
from routing_svc.store.engine import StoreTimeouts
from routing_svc.store.records import (
    AppendResult,
    EventRecord,
    FleetRecord,
    GroupItem,
    NetworkRecord,
    NewEvent,
)
from routing_svc.store.schema import events, fleets, networks, store_probe
from routing_svc.store.watchdog import ConnectionWatchdog

__all__ = [
    "FLEET_CREATED",
    "FLEET_DELETED",
    "Build",
    "BuildGroup",
    "EventLog",
    "FleetGroup",
    "Snapshot",
    "UncommittedAppend",
    "open_event_log",
]

Build = Callable[[list[EventRecord]], Sequence[NewEvent]]
"""``build(missed_events) -> new events``, called under the fleet's lock."""
BuildGroup = Callable[
    [list[EventRecord], list[int]], Sequence[Sequence[NewEvent] | RoutingSvcError]
]
"""``build(missed_events, fresh_indices) -> per fresh request, its events or its error``."""
Snapshot = Callable[[int], str | None]
"""``snapshot(new_version) -> state JSON or None``, called after ``build``."""

FLEET_CREATED = "fleet_created"
"""Kind of event number 1 of every fleet."""
FLEET_DELETED = "fleet_deleted"
"""Kind of the last event of a deleted fleet."""


class EventLog:
    """Event-log store over SQLite (default) or PostgreSQL.

    Parameters
    ----------
    url
        ``sqlite:///path/to/file.db`` or ``postgresql+psycopg://user@host/db``.
    busy_timeout_ms
        How long a SQLite writer waits for the write lock before failing.
    timeouts
        Bounds on every wait on the database (:class:`~routing_svc.store.engine.StoreTimeouts`);
        ``None`` (the default, for tools that read whole logs): the drivers' defaults.

    Notes
    -----
    The constructor only stores its arguments; :meth:`open` connects, checks
    the durability settings (see :mod:`routing_svc.store.engine`) and runs the
    migrations. Use it as a context manager or call :meth:`close`. One
    instance may be shared by threads.
    """

    def __init__(
        self, url: str, *, busy_timeout_ms: int = 30_000, timeouts: StoreTimeouts | None = None
    ) -> None:
        self.url = url
        self.busy_timeout_ms = busy_timeout_ms
        self.timeouts = timeouts
        self._engine: Engine | None = None
        self._watchdog: ConnectionWatchdog | None = None
        self.last_write_error: StorageError | None = None
        """The storage error of the last write, ``None`` when it committed (or none ran)."""
        # SQLite has one write lock per database: threads of this process queue
        # here instead of in SQLite's busy handler, which sleeps between retries.
        self._sqlite_writer = threading.Lock()
        self._impatient: Connection | None = None  # see try_append_groups_uncommitted
        self._checkpointer: WalCheckpointer | None = None

    # -- lifecycle -------------------------------------------------------------

    def open(self) -> Self:
        """Connect, refuse unsafe durability settings, migrate; return ``self``."""
        if self._engine is not None:
            return self
        self._watchdog = ConnectionWatchdog() if self.timeouts is not None else None
        engine = store_engine.create_store_engine(
            self.url,
            busy_timeout_ms=self.busy_timeout_ms,
            timeouts=self.timeouts,
            watchdog=self._watchdog,
        )
        try:
            with store_engine.storage_errors("open the event log"):
                with engine.connect() as connection:
                    store_engine.check_durability(connection)
                store_engine.upgrade(engine)
        except BaseException:
            engine.dispose()
            self._stop_watchdog()
            raise
        self._engine = engine
        database = engine.url.database
        if engine.dialect.name == "sqlite" and database:
            self._checkpointer = WalCheckpointer(database).start()
        return self

    def close(self) -> None:
        """Release every connection. Closing twice is harmless."""
        if self._engine is not None:
            if self._checkpointer is not None:
                self._checkpointer.stop()
                self._checkpointer = None
            with self._sqlite_writer:
                self._drop_impatient_connection()
            self._engine.dispose()
            self._engine = None
        self._stop_watchdog()

    def _stop_watchdog(self) -> None:
        if self._watchdog is not None:
            self._watchdog.stop()
            self._watchdog = None

    def __enter__(self) -> Self:
        return self.open()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def dialect(self) -> str:
        """``"sqlite"`` or ``"postgresql"``."""
        return self._require().dialect.name

    # -- health ----------------------------------------------------------------

    def check_reachable(self) -> None:
        """Run one trivial read; :class:`StorageError` when the database does not answer."""
        with self._read("reach the database") as conn:
            conn.exec_driver_sql("SELECT 1").scalar_one()

    def probe_write(self) -> None:
        """Commit one tiny write (the ``store_probe`` row) and note its outcome like any
        other write's; :class:`StorageError` when it fails."""
        with self._write("write the store probe") as conn:
            conn.execute(sa.update(store_probe).values(written_at=q.now()))

    def free_bytes(self) -> int | None:
        """Bytes free on the file system of a SQLite database (``None`` on PostgreSQL)."""
        engine = self._require()
        database = engine.url.database
        if engine.dialect.name != "sqlite" or not database:
            return None
        stats = os.statvfs(os.path.dirname(os.path.abspath(database)))
        return stats.f_bavail * stats.f_frsize

    def connections_in_use(self) -> int:
        """Connections the pool has lent out and not yet got back."""
        pool = self._require().pool
        checked_out = getattr(pool, "checkedout", None)
        return int(checked_out()) if checked_out is not None else 0

    def _note_write(self, error: StorageError | None) -> None:
        self.last_write_error = error

    # -- networks --------------------------------------------------------------

    def create_network(
        self, network_id: str, *, sha256: str, path: str, name: str, meta_json: str = "{}"
    ) -> NetworkRecord:
        """Register a network file; :class:`Conflict` if the id exists."""
        q.check_id(network_id, "network id")
        row: dict[str, object] = {"id": network_id, "sha256": sha256, "path": path}
        row |= {"name": name, "created_at": q.now(), "meta": meta_json}
        with self._write(f"create network {network_id!r}") as conn:
            if q.select_network(conn, network_id) is not None:
                raise Conflict(f"network {network_id!r} already exists")
            conn.execute(sa.insert(networks), row)
        return self.get_network(network_id)

    def rekey_network(self, network_id: str, *, old_sha256: str, new_sha256: str) -> NetworkRecord:
        """Store ``new_sha256`` as the hash of a network stored under ``old_sha256``.

        Only the hash changes: fleets name their network by id, so their events
        replay as before. A record that no longer holds ``old_sha256`` (another
        instance re-keyed it first) is left as it is.

        Raises
        ------
        UnknownNetwork
            If ``network_id`` is not registered.
        """
        with self._write(f"re-key network {network_id!r}") as conn:
            conn.execute(
                sa.update(networks)
                .where(networks.c.id == network_id, networks.c.sha256 == old_sha256)
                .values(sha256=new_sha256)
            )
        return self.get_network(network_id)

    def get_network(self, network_id: str) -> NetworkRecord:
        """Return a network; :class:`UnknownNetwork` if there is none."""
        with self._read("read a network") as conn:
            row = q.select_network(conn, network_id)
        if row is None:
            raise UnknownNetwork(f"no network {network_id!r}")
        return NetworkRecord.from_row(row)

    def list_networks(self) -> list[NetworkRecord]:
        """Return every network, ordered by id."""
        with self._read("list networks") as conn:
            rows = conn.execute(sa.select(networks).order_by(networks.c.id)).all()
        return [NetworkRecord.from_row(row) for row in rows]

    # -- fleets ----------------------------------------------------------------

    def create_fleet(
        self, fleet_id: str, network_id: str, config_json: str, created_event_payload: str
    ) -> FleetRecord:
        """Create a fleet and its ``fleet_created`` event (``seq`` 1) atomically.

        Raises
        ------
        Conflict
            If a fleet with this id exists or ever existed (ids are not reused).
        UnknownNetwork
            If ``network_id`` is not registered.
        """
        q.check_id(fleet_id, "fleet id")
        created = q.check_new_events([NewEvent(FLEET_CREATED, created_event_payload)])
        now = q.now()
        fleet: dict[str, object] = {
            "id": fleet_id,
            "network_id": network_id,
            "config": config_json,
            "version": 1,
        }
        fleet |= {"state": None, "snapshot_version": None, "created_at": now, "deleted": False}
        rows = q.event_rows(
            fleet_id, 0, created, idempotency_key=None, request_hash=None, created_at=now
        )
        with self._write(f"create fleet {fleet_id!r}") as conn:
            if q.select_fleet(conn, fleet_id) is not None:
                raise Conflict(f"fleet {fleet_id!r} already exists (fleet ids are never reused)")
            if q.select_network(conn, network_id) is None:
                raise UnknownNetwork(f"no network {network_id!r}")
            conn.execute(sa.insert(fleets), fleet)
            conn.execute(sa.insert(events), rows)
        return self.get_fleet(fleet_id)

    def get_fleet(self, fleet_id: str, *, include_deleted: bool = False) -> FleetRecord:
        """Return a fleet; :class:`UnknownFleet` if there is none (or it was deleted)."""
        with self._read("read a fleet") as conn:
            row = q.select_fleet(conn, fleet_id)
        if row is None or (row.deleted and not include_deleted):
            raise UnknownFleet(f"no fleet {fleet_id!r}")
        return FleetRecord.from_row(row)

    def list_fleets(
        self, *, network_id: str | None = None, include_deleted: bool = False
    ) -> list[FleetRecord]:
        """Return the fleets (optionally of one network), ordered by id."""
        query = sa.select(fleets).order_by(fleets.c.id)
        if network_id is not None:
            query = query.where(fleets.c.network_id == network_id)
        if not include_deleted:
            query = query.where(fleets.c.deleted == sa.false())
        with self._read("list fleets") as conn:
            rows = conn.execute(query).all()
        return [FleetRecord.from_row(row) for row in rows]

    def delete_fleet(self, fleet_id: str, *, payload_json: str = "{}") -> EventRecord:
        """Soft-delete a fleet: mark it deleted and append a ``fleet_deleted`` event.

        Returns
        -------
        EventRecord
            The ``fleet_deleted`` event, the last of the fleet's stream.
        """
        gone = q.check_new_events([NewEvent(FLEET_DELETED, payload_json)])
        with self._write(f"delete fleet {fleet_id!r}") as conn:
            version = q.lock_fleet(conn, fleet_id).version
            rows = q.event_rows(
                fleet_id, version, gone, idempotency_key=None, request_hash=None, created_at=q.now()
            )
            conn.execute(sa.insert(events), rows)
            conn.execute(
                sa.update(fleets)
                .where(fleets.c.id == fleet_id)
                .values(version=version + 1, deleted=True)
            )
        return q.records_of_rows(rows)[0]

    # -- events ----------------------------------------------------------------

    def append(
        self,
        fleet_id: str,
        *,
        expected_version: int,
        build: Build,
        idempotency_key: str | None = None,
        request_hash: str | None = None,
        snapshot: Snapshot | None = None,
    ) -> AppendResult:
        """Append the events that ``build`` returns, in one transaction.

        Parameters
        ----------
        fleet_id
            The fleet.
        expected_version
            The version of the caller's cached state. The stored events after
            it are passed to ``build`` so the caller can replay them first.
        build
            ``build(missed) -> [NewEvent, ...]``, called under the fleet's lock.
            It may return several events (numbered contiguously) or none (then
            nothing is written and the idempotency key is not recorded). If it
            raises, nothing is written and the exception propagates.
        idempotency_key, request_hash
            A retry with a known key returns the stored events without calling
            ``build``; :class:`Conflict` if its ``request_hash`` differs.
        snapshot
            ``snapshot(new_version) -> state JSON or None``, called after
            ``build`` when events were built; a string is saved, in the same
            transaction, as the fleet's snapshot at ``new_version``.

        Returns
        -------
        AppendResult
            Returned only after the transaction has committed.

        Raises
        ------
        UnknownFleet
            No such fleet, or it was deleted.
        Conflict
            ``expected_version`` is ahead of the log, or the idempotency key was
            used for a different request.
        InvalidInput
            A bad argument, or ``build`` returned something other than events.
        """

        def build_one(missed: list[EventRecord], fresh: list[int]) -> list[Sequence[NewEvent]]:
            return [build(missed)]

        (item,) = self.append_group(
            fleet_id,
            expected_version=expected_version,
            requests=[(idempotency_key, request_hash)],
            build=build_one,
            snapshot=snapshot,
        )
        if item.error is not None:
            raise item.error
        return AppendResult(fleet_id, item.version, item.events, item.missed, item.duplicate)

    def append_group(
        self,
        fleet_id: str,
        *,
        expected_version: int,
        requests: Sequence[tuple[str | None, str | None]],
        build: BuildGroup,
        snapshot: Snapshot | None = None,
    ) -> list[GroupItem]:
        """Append the events of several requests in one transaction (group commit).

        Parameters
        ----------
        fleet_id
            The fleet.
        expected_version
            The version of the caller's cached state; the stored events after
            it are passed to ``build``.
        requests
            One ``(idempotency_key, request_hash)`` per request, in order
            (either may be ``None``). A known key makes its request a
            duplicate (its stored events are returned, nothing is built) or,
            if the hash differs, fails it alone with :class:`Conflict`. A key
            repeated within the group is handled as a duplicate of its first
            occurrence: it gets the same events, or the same error.
        build
            ``build(missed, fresh) -> [events or error, ...]``, called under the
            fleet's lock with the missed events and the indices (into
            ``requests``) of the fresh requests; it returns one entry per fresh
            request: a list of :class:`NewEvent` (possibly empty: nothing is
            written and the key is not recorded) or a
            :class:`~routing_svc.errors.RoutingSvcError` (that request fails
            alone and nothing of it is written). It is not called when no
            request is fresh. If it raises, nothing at all is written and the
            exception propagates.
        snapshot
            ``snapshot(new_version) -> state JSON or None``, called once after
            ``build`` when events were built; a string is saved, in the same
            transaction, as the fleet's snapshot at ``new_version``.

        Returns
        -------
        list[GroupItem]
            One item per request, in order; returned only after the transaction
            has committed.

        Raises
        ------
        UnknownFleet
            No such fleet, or it was deleted.
        Conflict
            ``expected_version`` is ahead of the log.
        InvalidInput
            A bad argument, or ``build`` returned something other than one
            entry of events or an error per fresh request.
        """
        (items,) = self.append_groups(
            [FleetGroup(fleet_id, expected_version, tuple(requests), build, snapshot)]
        )
        return items

    def append_groups(self, groups: Sequence[FleetGroup]) -> list[list[GroupItem]]:
        """Commit the groups of several fleets in one transaction.

        Each :class:`FleetGroup` is handled exactly as :meth:`append_group`
        handles its arguments, in order, inside a single transaction: one
        commit (one ``fsync`` on SQLite) makes them all durable. If anything
        raises (an unknown or deleted fleet, a version conflict, a ``build``
        that raises), nothing of any group is written and the exception
        propagates; the caller can then retry the groups one by one.

        Returns
        -------
        list[list[GroupItem]]
            Per group, one item per request; returned only after the
            transaction has committed.
        """
        what = _check_groups(groups)
        with self._write(what) as conn:
            return _write_groups(conn, groups)

    def try_append_groups_uncommitted(
        self, groups: Sequence[FleetGroup]
    ) -> UncommittedAppend | None:
        """:meth:`append_groups` without its commit, if it can start without waiting.

        For a caller that must not block (an event loop): on SQLite, the
        transaction runs on a connection of its own that never waits for a lock.
        If another thread of this process is writing, or another process holds
        the database's write lock, it returns ``None`` and nothing happened. Else
        the groups are staged and written in a transaction left open, and the
        returned :class:`UncommittedAppend` holds their items; its
        :meth:`~UncommittedAppend.commit` (which waits for the disk, so call it
        from a worker thread) makes them durable. Until then every other writer
        of this process waits. On PostgreSQL it always returns ``None``.

        Raises
        ------
        Exception
            Whatever :meth:`append_groups` raises; the transaction is then rolled
            back and nothing is written.
        """
        what = _check_groups(groups)
        engine = self._require()
        if engine.dialect.name != "sqlite" or not self._sqlite_writer.acquire(blocking=False):
            return None
        try:
            conn = self._impatient_connection(what)
            with store_engine.storage_errors(what):
                conn.begin()
        except BaseException as error:
            self._drop_impatient_connection()
            self._sqlite_writer.release()
            if isinstance(error, StorageError) and store_engine.is_sqlite_busy(error):
                return None
            raise
        opened = UncommittedAppend(self, conn, what, [])
        try:
            with store_engine.storage_errors(what):
                opened.items = _write_groups(conn, groups)
        except BaseException:
            opened.rollback()  # (the connection stays open unless that fails too)
            raise
        return opened

    def _impatient_connection(self, what: str) -> Connection:
        """The SQLite connection of :meth:`try_append_groups_uncommitted`, kept open; its
        busy timeout is 0: it never waits for another process's write lock."""
        if self._impatient is None or self._impatient.closed or self._impatient.invalidated:
            with store_engine.storage_errors(what):
                conn = self._require().connect()
                conn.detach()  # closed, not pooled, when dropped: no other user gets timeout 0
                # on the driver's connection: a statement through ``conn`` would begin a
                # transaction (and take the write lock)
                driver = conn.connection.dbapi_connection
                assert driver is not None
                driver.execute("PRAGMA busy_timeout = 0")
            self._impatient = conn
        return self._impatient

    def _drop_impatient_connection(self) -> None:
        if self._impatient is not None:
            try:
                self._impatient.close()
            finally:
                self._impatient = None

    def events(self, fleet_id: str, *, after: int = 0, limit: int = 1000) -> list[EventRecord]:
        """Return up to ``limit`` events with ``seq > after``, in order (one page).

        Events of a deleted fleet stay readable.
        """
        q.check_version(after)
        if isinstance(limit, bool) or not isinstance(limit, int) or limit < 1:
            raise InvalidInput("limit must be an integer >= 1")
        with self._read("read events") as conn:
            if q.select_fleet(conn, fleet_id) is None:
                raise UnknownFleet(f"no fleet {fleet_id!r}")
            return q.select_events(conn, fleet_id, after=after, limit=limit)

    def events_since(self, fleet_id: str, version: int) -> list[EventRecord]:
        """Return every event with ``seq > version``, in order."""
        q.check_version(version)
        with self._read("read events") as conn:
            if q.select_fleet(conn, fleet_id) is None:
                raise UnknownFleet(f"no fleet {fleet_id!r}")
            return q.select_events(conn, fleet_id, after=version)

    def save_snapshot(self, fleet_id: str, version: int, state_json: str) -> bool:
        """Keep ``state_json`` as the fleet's state at ``version``.

        Returns
        -------
        bool
            ``False`` (and nothing changes) when a snapshot at ``version`` or
            later is already stored.

        Raises
        ------
        Conflict
            ``version`` is ahead of the fleet's version.
        """
        q.check_version(version)
        with self._write(f"snapshot fleet {fleet_id!r}") as conn:
            row = q.lock_fleet(conn, fleet_id)
            if version > row.version:
                raise Conflict(f"fleet {fleet_id!r} is at version {row.version}, not {version}")
            if row.snapshot_version is not None and row.snapshot_version >= version:
                return False
            conn.execute(
                sa.update(fleets)
                .where(fleets.c.id == fleet_id)
                .values(state=state_json, snapshot_version=version)
            )
        return True

    def integrity_check(self) -> list[str]:
        """Return the problems found (an empty list when all is well).

        On SQLite this runs ``PRAGMA integrity_check``; on both backends it
        checks that every fleet's events are numbered ``1..version`` without gaps.
        """
        problems: list[str] = []
        with self._read("check integrity") as conn:
            if conn.dialect.name == "sqlite":
                rows = conn.exec_driver_sql("PRAGMA integrity_check").scalars().all()
                problems += [str(row) for row in rows if str(row) != "ok"]
            problems += q.fleet_event_stats(conn)
        return problems

    # -- plumbing --------------------------------------------------------------

    def _require(self) -> Engine:
        if self._engine is None:
            raise StorageError("the event log is not open (call open() or use it in a with block)")
        return self._engine

    @contextmanager
    def _write(self, what: str) -> Iterator[Connection]:
        """A transaction that holds the write lock (SQLite) until it ends.

        Its outcome is noted in :attr:`last_write_error` (a domain error raised
        inside, such as :class:`Conflict`, notes nothing); a connection lost at
        the commit raises :class:`CommitOutcomeUnknown` on PostgreSQL.
        """
        engine = self._require()
        gate = self._sqlite_writer if engine.dialect.name == "sqlite" else nullcontext()
        try:
            with gate, store_engine.storage_errors(what), engine.connect() as conn:
                transaction = conn.begin()
                try:
                    yield conn
                except BaseException:
                    with suppress(sa.exc.SQLAlchemyError):
                        transaction.rollback()
                    raise
                store_engine.commit(transaction, what)
        except StorageError as error:
            self._note_write(error)
            raise
        self._note_write(None)

    @contextmanager
    def _read(self, what: str) -> Iterator[Connection]:
        """A read-only transaction (a deferred ``BEGIN`` on SQLite)."""
        engine = self._require()
        with store_engine.storage_errors(what), engine.connect() as conn:
            conn.execution_options(**{store_engine.BEGIN_MODE: "DEFERRED"})
            yield conn


def _check_groups(groups: Sequence[FleetGroup]) -> str:
    """Check :meth:`EventLog.append_groups`'s arguments; what the append is called in errors."""
    for group in groups:
        q.check_version(group.expected_version)
        for key, digest in group.requests:
            q.check_key(key, "idempotency key")
            q.check_key(digest, "request hash")
    if len({group.fleet_id for group in groups}) != len(groups):
        raise InvalidInput("append_groups takes at most one group per fleet")
    return "append to fleets " + ", ".join(repr(g.fleet_id) for g in groups)


def _write_groups(conn: Connection, groups: Sequence[FleetGroup]) -> list[list[GroupItem]]:
    """Stage and write ``groups`` in the open write transaction ``conn``; their items."""
    versions = q.lock_fleets(conn, [group.fleet_id for group in groups])
    created_at = q.now()  # one moment for the whole transaction
    staged = [_stage_in(conn, group, versions[group.fleet_id], created_at) for group in groups]
    q.insert_event_rows(conn, [row for stage in staged for row in stage.rows])
    q.move_versions(conn, [stage.move for stage in staged if stage.move is not None])
    return [stage.items for stage in staged]


class UncommittedAppend:
    """The open transaction of :meth:`EventLog.try_append_groups_uncommitted`.

    ``items`` are the groups' items, valid once :meth:`commit` returned.
    Exactly one of :meth:`commit` and :meth:`rollback` must be called; both
    may run on another thread than the one that started the transaction.
    """

    def __init__(
        self, log: EventLog, conn: Connection, what: str, items: list[list[GroupItem]]
    ) -> None:
        self._log = log
        self._conn = conn
        self._what = what
        self.items = items

    def commit(self) -> None:
        """Commit (one ``fsync``); on failure nothing is written and the error is raised.

        The ``COMMIT`` goes straight to the driver: the calling thread then releases the
        interpreter lock once, at SQLite's commit, after a few microseconds of Python
        (SQLAlchemy's commit runs more, and the driver's ``commit()`` releases the lock
        twice: a thread that must get it back mid-way can wait for a busy event loop,
        see :mod:`routing_svc.service.committer`). SQLAlchemy's commit then only ends its
        own transaction: the driver has nothing left to commit.
        """
        self._end(self._commit_on_driver, f"commit ({self._what})", committing=True)

    def _commit_on_driver(self) -> None:
        conn = self._conn
        driver = conn.connection.dbapi_connection
        assert driver is not None
        driver.execute("COMMIT")
        conn.commit()

    def rollback(self) -> None:
        """Write nothing."""
        self._end(self._conn.rollback, f"roll back ({self._what})", committing=False)

    def _end(self, finish: Callable[[], None], what: str, *, committing: bool) -> None:
        """End the transaction with ``finish``; give the write lock back in any case and
        drop the connection if that failed. A commit's outcome is noted as a write's."""
        log = self._log
        try:
            with store_engine.storage_errors(what):
                finish()
        except BaseException as error:
            log._drop_impatient_connection()
            if committing and isinstance(error, StorageError):
                log._note_write(error)
            raise
        finally:
            log._sqlite_writer.release()
        if committing:
            log._note_write(None)


def _checked_group(
    built: Sequence[Sequence[NewEvent] | RoutingSvcError], expected: int
) -> list[list[NewEvent] | RoutingSvcError]:
    """Check ``build``'s answer: one entry of events or an error per fresh request."""
    if isinstance(built, str | bytes) or not isinstance(built, Sequence):
        raise InvalidInput("a group build must return a list with one entry per fresh request")
    entries = list(built)
    if len(entries) != expected:
        raise InvalidInput(
            f"a group build returned {len(entries)} entries for {expected} fresh requests"
        )
    return [
        entry if isinstance(entry, RoutingSvcError) else q.check_new_events(entry)
        for entry in entries
    ]


def open_event_log(
    url: str, *, busy_timeout_ms: int = 30_000, timeouts: StoreTimeouts | None = None
) -> EventLog:
    """Create an :class:`EventLog` for ``url`` and open it."""
    return EventLog(url, busy_timeout_ms=busy_timeout_ms, timeouts=timeouts).open()


@dataclass(frozen=True, slots=True)
class FleetGroup:
    """The arguments of :meth:`EventLog.append_group` for one fleet."""

    fleet_id: str
    expected_version: int
    requests: tuple[tuple[str | None, str | None], ...]
    build: BuildGroup
    snapshot: Snapshot | None = None


@dataclass(frozen=True, slots=True)
class _Staged:
    """One fleet's share of a transaction, computed but not yet written."""

    rows: list[dict[str, Any]]
    move: tuple[str, int, str | None] | None
    """``(fleet, new version, snapshot or None)``, ``None`` when nothing is written."""
    items: list[GroupItem]


def _stage_in(conn: Connection, group: FleetGroup, version: int, created_at: datetime) -> _Staged:
    """Build one fleet's group inside the open transaction ``conn``, whose row is
    locked at ``version``, with events stamped ``created_at``; the caller writes the
    rows and the version."""
    fleet_id, expected_version = group.fleet_id, group.expected_version
    requests, build, snapshot = group.requests, group.build, group.snapshot
    if expected_version > version:
        raise Conflict(
            f"fleet {fleet_id!r} is at version {version}; "
            f"the caller's cache claims version {expected_version}"
        )
    stored: dict[str, list[EventRecord]] = {}
    first_index: dict[str, int] = {}
    fresh: list[int] = []
    repeats: dict[int, int] = {}  # index of a repeated key -> its first occurrence
    for index, (key, _) in enumerate(requests):
        if key is None:
            fresh.append(index)
        elif key in first_index:
            repeats[index] = first_index[key]
        else:
            first_index[key] = index
            prior = q.keyed_batch(conn, fleet_id, key)
            if prior:
                stored[key] = prior
            else:
                fresh.append(index)
    # the events after the caller's version, if other writers appended any
    missed = (
        tuple(q.select_events(conn, fleet_id, after=expected_version))
        if version > expected_version
        else ()
    )
    built: list[list[NewEvent] | RoutingSvcError] = []
    if fresh:
        built = _checked_group(build(list(missed), list(fresh)), len(fresh))
    rows: list[dict[str, Any]] = []
    outcome: dict[int, tuple[tuple[EventRecord, ...], RoutingSvcError | None]] = {}
    for index, entry in zip(fresh, built, strict=True):
        if isinstance(entry, RoutingSvcError):
            outcome[index] = ((), entry)
            continue
        key, digest = requests[index]
        mine = q.event_rows(
            fleet_id,
            version + len(rows),
            entry,
            idempotency_key=key,
            request_hash=digest,
            created_at=created_at,
        )
        rows += mine
        outcome[index] = (q.records_of_rows(mine), None)
    new_version = version + len(rows)
    move: tuple[str, int, str | None] | None = None
    if rows:
        state = snapshot(new_version) if snapshot is not None else None
        if state is not None and not isinstance(state, str):
            raise InvalidInput("snapshot must return JSON text (str) or None")
        move = (fleet_id, new_version, state)
    items: list[GroupItem] = []
    for index, (key, digest) in enumerate(requests):
        first = repeats.get(index, index)
        duplicate = first != index
        if key is not None and key in stored:
            prior_events = stored[key]
            if prior_events[0].request_hash != digest:
                error: RoutingSvcError = Conflict(
                    f"idempotency key {key!r} was used for another request"
                )
                items.append(GroupItem(new_version, (), missed, False, error))
            else:
                items.append(GroupItem(new_version, tuple(prior_events), missed, True))
            continue
        events_of, failed = outcome[first]
        if duplicate and requests[first][1] != digest:
            failed = Conflict(f"idempotency key {key!r} was used for another request")
        if failed is not None:
            items.append(GroupItem(new_version, (), missed, False, failed))
        else:
            items.append(GroupItem(new_version, events_of, missed, duplicate))
    return _Staged(rows, move, items)
