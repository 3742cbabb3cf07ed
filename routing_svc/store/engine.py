"""Engines for the event-log store: durability settings, checks and migrations.

Two backends share one schema:

* **SQLite** (``sqlite:///path``), the embedded default. Every connection gets
  ``journal_mode=WAL`` (checked: an in-memory database cannot do WAL and is
  refused), ``synchronous=FULL``, a ``busy_timeout``, ``foreign_keys=ON`` and
  no automatic checkpoints (the event log runs them on a thread:
  :mod:`routing_svc.store.checkpoint`).
  Following the pysqlite recipe of the SQLAlchemy documentation, the driver's
  own transaction handling is switched off (``isolation_level = None``) and a
  ``begin`` hook emits ``BEGIN IMMEDIATE`` itself, so a writer takes the write
  lock before it reads and waits (up to the busy timeout) instead of failing
  with "database is locked" on upgrade. Read-only connections ask for a plain
  deferred ``BEGIN`` through the :data:`BEGIN_MODE` execution option.
* **PostgreSQL** (``postgresql+psycopg://...``; a bare ``postgresql://`` is
  taken to mean psycopg 3). Opening refuses a server whose ``fsync``,
  ``synchronous_commit`` or ``full_page_writes`` is off: acknowledged events
  must survive a crash.

:class:`StoreTimeouts` bounds every wait on the database: the connect
timeout, TCP keepalives and ``tcp_user_timeout`` (libpq), the server's
``statement_timeout``, ``lock_timeout`` and
``idle_in_transaction_session_timeout`` (sent in the connection's start-up
``options``; options in the URL win), the pool's checkout timeout, and a
client-side bound on each lent-out connection
(:mod:`routing_svc.store.watchdog`), which also covers the liveness ping the
pool runs before lending a connection out.

:func:`upgrade` runs the Alembic migrations that live inside the package.
"""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import sqlalchemy as sa
from alembic import command
from alembic.config import Config
from sqlalchemy import event
from sqlalchemy.engine import Connection, Engine, make_url

from routing_svc.errors import CommitOutcomeUnknown, Conflict, StorageError, StorageTimeout
from routing_svc.store.watchdog import ConnectionWatchdog

__all__ = [
    "BEGIN_MODE",
    "MIGRATIONS_DIR",
    "StoreTimeouts",
    "check_durability",
    "commit",
    "create_store_engine",
    "fault_reason",
    "is_sqlite_busy",
    "storage_errors",
    "upgrade",
]

BEGIN_MODE = "routing_svc_sqlite_begin"
"""Execution option naming the SQLite ``BEGIN`` mode (``IMMEDIATE`` by default)."""

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"
"""The Alembic script directory shipped with the package."""

_MIGRATION_LOCK_KEY = 0x726F7574  # pg_advisory_xact_lock key serialising migrations
_PG_DURABILITY = ("fsync", "synchronous_commit", "full_page_writes")
_SQLITE_BEGIN = {mode: f"BEGIN {mode}" for mode in ("IMMEDIATE", "DEFERRED", "EXCLUSIVE")}
"""The statement that begins a transaction in each BEGIN mode."""


@dataclass(frozen=True, slots=True)
class StoreTimeouts:
    """Bounds on the store's waits on its database (PostgreSQL unless said).

    Attributes
    ----------
    connect_s
        libpq ``connect_timeout``: the whole connection set-up (libpq's minimum is 2).
    pool_checkout_s
        How long a caller waits for a free connection of the pool (both backends).
    statement_ms, lock_ms
        The server's ``statement_timeout`` and ``lock_timeout``, for every statement.
    idle_in_transaction_ms
        The server's ``idle_in_transaction_session_timeout``: a client that vanished
        inside a transaction loses its session, and its row locks, after this long.
    lent_s
        Client-side bound on a connection lent out by the pool, from the liveness
        ping to its return (:mod:`routing_svc.store.watchdog`); ``None``: unbounded.
    keepalives_idle_s, keepalives_interval_s, keepalives_count
        TCP keepalives (libpq ``keepalives_*``): a silent peer is noticed after about
        ``idle + interval * count`` seconds.
    tcp_user_timeout_ms
        libpq ``tcp_user_timeout``: sent data left unacknowledged this long errors
        the socket out.
    """

    connect_s: int = 5
    pool_checkout_s: float = 5.0
    statement_ms: int = 5_000
    lock_ms: int = 5_000
    idle_in_transaction_ms: int = 10_000
    lent_s: float | None = 10.0
    keepalives_idle_s: int = 10
    keepalives_interval_s: int = 3
    keepalives_count: int = 3
    tcp_user_timeout_ms: int = 10_000

    def libpq_parameters(self) -> dict[str, str]:
        """The libpq connection parameters these bounds set."""
        options = (
            f"-c statement_timeout={int(self.statement_ms)} -c lock_timeout={int(self.lock_ms)} "
            f"-c idle_in_transaction_session_timeout={int(self.idle_in_transaction_ms)}"
        )
        return {
            "connect_timeout": str(int(self.connect_s)),
            "keepalives": "1",
            "keepalives_idle": str(int(self.keepalives_idle_s)),
            "keepalives_interval": str(int(self.keepalives_interval_s)),
            "keepalives_count": str(int(self.keepalives_count)),
            "tcp_user_timeout": str(int(self.tcp_user_timeout_ms)),
            "options": options,
        }


def create_store_engine(
    url: str,
    *,
    busy_timeout_ms: int,
    timeouts: StoreTimeouts | None = None,
    watchdog: ConnectionWatchdog | None = None,
) -> Engine:
    """Create (without connecting) an engine for a supported database URL.

    Parameters
    ----------
    url
        ``sqlite:///path/to/file.db`` or ``postgresql+psycopg://user@host/db``.
    busy_timeout_ms
        How long a SQLite connection waits for the write lock.
    timeouts
        Bounds on the waits (see :class:`StoreTimeouts`); ``None``: the drivers'
        defaults (a tool that reads a whole log, such as ``routing-svc replay``).
    watchdog
        Enforces ``timeouts.lent_s`` on PostgreSQL (the caller stops it).

    Returns
    -------
    Engine
        An engine whose connections carry the durability settings above.

    Raises
    ------
    StorageError
        For a backend other than SQLite and PostgreSQL.
    """
    parsed = make_url(url)
    backend = parsed.get_backend_name()
    pool: dict[str, Any] = {}
    if timeouts is not None:
        pool["pool_timeout"] = timeouts.pool_checkout_s
    if backend == "sqlite":
        engine = sa.create_engine(parsed, **pool)
        _install_sqlite_hooks(engine, busy_timeout_ms=busy_timeout_ms)
        return engine
    if backend == "postgresql":
        if parsed.drivername == "postgresql":
            parsed = parsed.set(drivername="postgresql+psycopg")
        if timeouts is None:
            return sa.create_engine(parsed, pool_pre_ping=True)
        query = dict(parsed.query)
        for name, value in timeouts.libpq_parameters().items():
            given = query.get(name)
            if name == "options" and isinstance(given, str):
                query[name] = f"{value} {given}"  # the URL's options come last and win
            elif given is None:
                query[name] = value
        engine = sa.create_engine(parsed.set(query=query), **pool)
        _install_pg_checkout_bound(engine, timeouts, watchdog or ConnectionWatchdog())
        return engine
    raise StorageError(
        f"unsupported database URL {parsed!r}: use sqlite:/// or postgresql+psycopg://"
    )


def _install_pg_checkout_bound(
    engine: Engine, timeouts: StoreTimeouts, watchdog: ConnectionWatchdog
) -> None:
    """Ping each connection the pool lends out, both bounded by ``watchdog``.

    This replaces ``pool_pre_ping``, whose ping runs before any checkout hook and
    so could wait forever on a connection whose peer stopped answering.
    """
    ping_bound = float(timeouts.connect_s)
    lent_bound = timeouts.lent_s
    dialect = engine.dialect

    @event.listens_for(engine, "connect")
    def _on_connect(_dbapi_connection: Any, record: Any) -> None:
        record.info["routing_svc_fresh"] = True

    @event.listens_for(engine, "checkout")
    def _on_checkout(dbapi_connection: Any, record: Any, _proxy: Any) -> None:
        if not record.info.pop("routing_svc_fresh", False):
            watchdog.watch(record, dbapi_connection, ping_bound)
            try:
                dialect.do_ping(dbapi_connection)
            except Exception as error:
                watchdog.release(record)
                # the pool drops this connection (and older ones) and connects anew
                raise sa.exc.DisconnectionError(str(error)) from error
        if lent_bound is not None:
            watchdog.watch(record, dbapi_connection, lent_bound)
        else:
            watchdog.release(record)

    @event.listens_for(engine, "checkin")
    def _on_checkin(_dbapi_connection: Any, record: Any) -> None:
        watchdog.release(record)

    @event.listens_for(engine, "invalidate")
    def _on_invalidate(_dbapi_connection: Any, record: Any, _error: Any) -> None:
        watchdog.release(record)

    @event.listens_for(engine, "close")
    def _on_close(_dbapi_connection: Any, record: Any) -> None:
        watchdog.release(record)


def _install_sqlite_hooks(engine: Engine, *, busy_timeout_ms: int) -> None:
    """Attach the connect/begin hooks of the pysqlite recipe to ``engine``."""

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, _record: Any) -> None:
        dbapi_connection.isolation_level = None  # we emit BEGIN ourselves
        cursor = dbapi_connection.cursor()
        try:
            cursor.execute(f"PRAGMA busy_timeout = {int(busy_timeout_ms)}")
            mode = _switch_to_wal(cursor, busy_timeout_ms=busy_timeout_ms)
            if str(mode).lower() != "wal":
                raise StorageError(
                    f"SQLite refused write-ahead logging (journal_mode is {mode!r}); "
                    "the event log needs a database file on a local file system"
                )
            cursor.execute("PRAGMA synchronous = FULL")
            cursor.execute("PRAGMA foreign_keys = ON")
            # checkpoints run beside the commits, see routing_svc.store.checkpoint
            cursor.execute("PRAGMA wal_autocheckpoint = 0")
        finally:
            cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(connection: Connection) -> None:
        mode = connection.get_execution_options().get(BEGIN_MODE, "IMMEDIATE")
        statement = _SQLITE_BEGIN.get(mode)
        if statement is None:
            raise StorageError(f"unknown SQLite BEGIN mode {mode!r}")
        # straight to the driver: a statement through ``connection`` would cost every
        # transaction SQLAlchemy's execution machinery (its errors are handled alike,
        # see storage_errors)
        driver = connection.connection.dbapi_connection
        assert driver is not None
        driver.execute(statement)


def _switch_to_wal(cursor: Any, *, busy_timeout_ms: int) -> str:
    """Run ``PRAGMA journal_mode = WAL`` and return the journal mode in force.

    Changing the journal mode of a fresh database needs an exclusive lock, and
    SQLite answers "database is locked" at once, without its busy handler, when
    another connection is changing it at the same moment. The pragma is retried
    with a growing pause until the busy timeout is spent.
    """
    deadline = time.monotonic() + busy_timeout_ms / 1000.0
    pause = 0.001
    while True:
        try:
            return str(cursor.execute("PRAGMA journal_mode = WAL").fetchone()[0])
        except sqlite3.OperationalError as error:
            locked = "locked" in str(error) or "busy" in str(error)
            if not locked or time.monotonic() + pause > deadline:
                raise
        time.sleep(pause)
        pause = min(2 * pause, 0.05)


def check_durability(connection: Connection) -> None:
    """Refuse a database that could lose acknowledged events.

    Parameters
    ----------
    connection
        A connection of the store's engine.

    Raises
    ------
    StorageError
        On SQLite when the journal is not WAL or ``synchronous`` is not FULL; on
        PostgreSQL when ``fsync``, ``synchronous_commit`` or
        ``full_page_writes`` is off.
    """
    if connection.dialect.name == "sqlite":
        journal = str(connection.exec_driver_sql("PRAGMA journal_mode").scalar_one())
        synchronous = int(connection.exec_driver_sql("PRAGMA synchronous").scalar_one())
        if journal.lower() != "wal" or synchronous != 2:
            raise StorageError(
                f"SQLite durability settings not in force (journal_mode={journal}, "
                f"synchronous={synchronous}; need wal and 2=FULL)"
            )
        return
    unsafe = []
    for setting in _PG_DURABILITY:
        value = str(connection.exec_driver_sql(f"SHOW {setting}").scalar_one())
        if value.lower() == "off":
            unsafe.append(f"{setting}=off")
    if unsafe:
        raise StorageError(
            "refusing to use a PostgreSQL server that can lose committed events ("
            + ", ".join(unsafe)
            + "): turn these settings on in postgresql.conf (or for this role/session)"
        )


def upgrade(engine: Engine) -> None:
    """Bring the schema to the newest migration, in one transaction.

    Concurrent openers are serialised: on SQLite by ``BEGIN IMMEDIATE``, on
    PostgreSQL by a transaction-scoped advisory lock; the later ones find the
    schema current and do nothing.
    """
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR).replace("%", "%%"))
    with engine.begin() as connection:
        if connection.dialect.name == "postgresql":
            connection.execute(
                sa.text("SELECT pg_advisory_xact_lock(:key)"), {"key": _MIGRATION_LOCK_KEY}
            )
        config.attributes["connection"] = connection
        command.upgrade(config, "head")


def is_sqlite_busy(error: StorageError) -> bool:
    """Whether ``error`` (from :func:`storage_errors`) is SQLite's "database is locked"."""
    cause = error.__cause__
    orig = getattr(cause, "orig", cause)
    return isinstance(orig, sqlite3.OperationalError) and (
        "locked" in str(orig) or "busy" in str(orig)
    )


_FAULTS = {
    "full": "the store is out of space",
    "unreachable": "the store is unreachable",
    "timeout": "the store did not answer in time",
    "failed": "the store reported an error",
}
_PG_FULL = "53100"  # disk_full
_PG_TIMEOUTS = ("57014", "55P03")  # query_canceled (statement_timeout), lock_not_available


def fault_reason(error: StorageError) -> str:
    """A short public description of a storage failure (no host, driver or SQL)."""
    if isinstance(error, StorageTimeout):
        return _FAULTS["timeout"]
    if isinstance(error, CommitOutcomeUnknown):
        return _FAULTS["unreachable"]
    cause = error.__cause__
    orig = getattr(cause, "orig", cause)
    text = str(orig).lower()
    if isinstance(orig, sqlite3.Error) and ("full" in text or "no space" in text):
        return _FAULTS["full"]
    sqlstate = getattr(orig, "sqlstate", None)
    if sqlstate == _PG_FULL:
        return _FAULTS["full"]
    if sqlstate in _PG_TIMEOUTS or isinstance(cause, sa.exc.TimeoutError):
        return _FAULTS["timeout"]
    if (
        isinstance(cause, sa.exc.DBAPIError)
        and (cause.connection_invalidated or isinstance(orig, OSError) or sqlstate is None)
        and not isinstance(orig, sqlite3.Error)
    ):
        return _FAULTS["unreachable"]
    return _FAULTS["failed"]


def commit(transaction: sa.engine.Transaction, what: str) -> None:
    """Commit ``transaction``; a PostgreSQL connection lost at the commit raises
    :class:`CommitOutcomeUnknown` (the server may have committed before it went).

    On SQLite a failed ``COMMIT`` leaves nothing committed, so its error stays a
    plain driver error (made a :class:`StorageError` by :func:`storage_errors`).
    """
    try:
        transaction.commit()
    except sa.exc.DBAPIError as error:
        if error.connection_invalidated and transaction.connection.dialect.name != "sqlite":
            raise CommitOutcomeUnknown(
                f"connection lost at the commit of {what}: {error}"
            ) from error
        raise


@contextmanager
def storage_errors(what: str) -> Iterator[None]:
    """Turn database driver errors into :class:`Conflict` / :class:`StorageError`.

    A unique-key violation (two writers creating the same id at once) becomes
    :class:`Conflict`; any other driver error, "database is locked" after the
    busy timeout or a lost PostgreSQL connection included, :class:`StorageError`.
    """
    try:
        yield
    except sa.exc.IntegrityError as error:
        raise Conflict(f"could not {what}: {error.orig}") from error
    except sa.exc.SQLAlchemyError as error:
        raise StorageError(f"could not {what}: {error}") from error
    # the write path's hot statements on SQLite use the driver directly
    except sqlite3.IntegrityError as error:
        raise Conflict(f"could not {what}: {error}") from error
    except sqlite3.Error as error:
        raise StorageError(f"could not {what}: {error}") from error
