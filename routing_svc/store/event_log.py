"""The event log: each fleet as a numbered stream of JSON events.

A fleet's state is the replay of its events; the ``fleets`` row keeps its
version (the last event's ``seq``) and an optional snapshot so restarts are
fast. :meth:`EventLog.append_groups` is the one way to add events: in one
transaction it locks the fleets' rows (``SELECT ... FOR UPDATE`` on
PostgreSQL, the database write lock taken by ``BEGIN IMMEDIATE`` on SQLite),
answers a retried idempotency key from the log, hands the events the caller
has not seen yet to each group's ``build`` callback, and writes what ``build``
returns with contiguous numbers (:mod:`~routing_svc.store.staging`). Workers in
several processes or on several hosts therefore apply events in one order,
each replaying what it missed before computing the next. A call returns only
after its transaction has committed;
:meth:`EventLog.try_append_groups_uncommitted` leaves the commit to its caller.

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
from types import TracebackType
from typing import Protocol, Self

import sqlalchemy as sa
from sqlalchemy.engine import Connection, Engine

from routing_svc.errors import Conflict, InvalidInput, StorageError, UnknownFleet, UnknownNetwork
from routing_svc.store import engine as store_engine
from routing_svc.store import queries as q
from routing_svc.store.checkpoint import WalCheckpointer
from routing_svc.store.engine import StoreTimeouts
from routing_svc.store.records import (
    EventRecord,
    FleetRecord,
    GroupItem,
    NetworkRecord,
    NewEvent,
)
from routing_svc.store.schema import events, fleets, networks, store_probe
from routing_svc.store.staging import FleetGroup, check_groups, write_groups
from routing_svc.store.watchdog import ConnectionWatchdog

__all__ = [
    "FLEET_CREATED",
    "FLEET_DELETED",
    "EventLog",
    "UncommittedAppend",
    "open_event_log",
]

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

    @property
    def engine(self) -> Engine:
        """The open log's SQLAlchemy engine (for reads and event listeners; every write
        goes through the log's own methods)."""
        return self._require()

    @property
    def checkpointer(self) -> WalCheckpointer | None:
        """The thread that checkpoints a SQLite database's write-ahead log (``None`` on
        PostgreSQL, or when the log is closed)."""
        return self._checkpointer

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

    def append_groups(self, groups: Sequence[FleetGroup]) -> list[list[GroupItem]]:
        """Commit the groups of several fleets in one transaction.

        Each :class:`~routing_svc.store.staging.FleetGroup` is staged in order
        (:func:`~routing_svc.store.staging.stage_group`) inside a single transaction: one
        commit (one ``fsync`` on SQLite) makes them all durable. If anything
        raises (an unknown or deleted fleet, a version conflict, a ``build``
        that raises), nothing of any group is written and the exception
        propagates; the caller can then retry the groups one by one.

        Returns
        -------
        list[list[GroupItem]]
            Per group, one item per request; returned only after the
            transaction has committed.

        Raises
        ------
        UnknownFleet
            No such fleet, or it was deleted.
        Conflict
            A group's ``expected_version`` is ahead of the log.
        InvalidInput
            A bad argument, two groups of one fleet, or a ``build`` that
            returned something other than one entry per fresh request.
        """
        what = check_groups(groups)
        with self._write(what) as conn:
            return write_groups(conn, groups)

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
        what = check_groups(groups)
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
        opened = UncommittedAppend(conn, what, [], self._end_uncommitted)
        try:
            with store_engine.storage_errors(what):
                opened.items = write_groups(conn, groups)
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

    def _end_uncommitted(self, error: BaseException | None, *, committing: bool) -> None:
        """An :class:`UncommittedAppend` ended (with ``error`` if ending it failed): give
        the write lock back, drop the connection after a failure, note a commit's outcome
        as a write's."""
        try:
            if error is not None:
                self._drop_impatient_connection()
                if committing and isinstance(error, StorageError):
                    self._note_write(error)
        finally:
            self._sqlite_writer.release()
        if committing and error is None:
            self._note_write(None)

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


class TransactionEnded(Protocol):
    """``ended(error, committing=...)``: an :class:`UncommittedAppend` ended, with the
    exception that ending it raised (``None`` if it did not)."""

    def __call__(self, error: BaseException | None, *, committing: bool) -> None: ...


class UncommittedAppend:
    """The open transaction of :meth:`EventLog.try_append_groups_uncommitted`.

    ``items`` are the groups' items, valid once :meth:`commit` returned.
    Exactly one of :meth:`commit` and :meth:`rollback` must be called; both
    may run on another thread than the one that started the transaction.

    Parameters
    ----------
    connection
        The connection whose transaction is open.
    what
        What the append is called in errors.
    items
        The groups' items.
    ended
        Called once the transaction ended; the log gives its write lock back there.
    """

    def __init__(
        self,
        connection: Connection,
        what: str,
        items: list[list[GroupItem]],
        ended: TransactionEnded,
    ) -> None:
        self._connection = connection
        self._what = what
        self._ended = ended
        self.items = items

    @property
    def connection(self) -> Connection:
        """The connection whose transaction is open."""
        return self._connection

    def commit(self) -> None:
        """Commit (one ``fsync``); on failure nothing is written and the error is raised.

        The ``COMMIT`` goes straight to the driver: the calling thread then releases the
        interpreter lock once, at SQLite's commit, after a few microseconds of Python
        (SQLAlchemy's commit runs more, and the driver's ``commit()`` releases the lock
        twice: a thread that must get it back mid-way can wait for a busy event loop,
        see :mod:`routing_svc.service.write_path.committer`). SQLAlchemy's commit then
        only ends its own transaction: the driver has nothing left to commit.
        """
        self._end(self._commit_on_driver, f"commit ({self._what})", committing=True)

    def _commit_on_driver(self) -> None:
        conn = self._connection
        driver = conn.connection.dbapi_connection
        assert driver is not None
        driver.execute("COMMIT")
        conn.commit()

    def rollback(self) -> None:
        """Write nothing."""
        self._end(self._connection.rollback, f"roll back ({self._what})", committing=False)

    def _end(self, finish: Callable[[], None], what: str, *, committing: bool) -> None:
        """End the transaction with ``finish``, then tell the log how it went."""
        try:
            with store_engine.storage_errors(what):
                finish()
        except BaseException as error:
            self._ended(error, committing=committing)
            raise
        self._ended(None, committing=committing)


def open_event_log(
    url: str, *, busy_timeout_ms: int = 30_000, timeouts: StoreTimeouts | None = None
) -> EventLog:
    """Create an :class:`EventLog` for ``url`` and open it."""
    return EventLog(url, busy_timeout_ms=busy_timeout_ms, timeouts=timeouts).open()
