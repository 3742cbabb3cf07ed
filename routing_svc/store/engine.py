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

:func:`upgrade` runs the Alembic migrations that live inside the package.
"""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import sqlalchemy as sa
from alembic import command
from alembic.config import Config
from sqlalchemy import event
from sqlalchemy.engine import Connection, Engine, make_url

from routing_svc.errors import Conflict, StorageError

__all__ = [
    "BEGIN_MODE",
    "MIGRATIONS_DIR",
    "check_durability",
    "create_store_engine",
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


def create_store_engine(url: str, *, busy_timeout_ms: int) -> Engine:
    """Create (without connecting) an engine for a supported database URL.

    Parameters
    ----------
    url
        ``sqlite:///path/to/file.db`` or ``postgresql+psycopg://user@host/db``.
    busy_timeout_ms
        How long a SQLite connection waits for the write lock.

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
    if backend == "sqlite":
        engine = sa.create_engine(parsed)
        _install_sqlite_hooks(engine, busy_timeout_ms=busy_timeout_ms)
        return engine
    if backend == "postgresql":
        if parsed.drivername == "postgresql":
            parsed = parsed.set(drivername="postgresql+psycopg")
        return sa.create_engine(parsed, pool_pre_ping=True)
    raise StorageError(
        f"unsupported database URL {parsed!r}: use sqlite:/// or postgresql+psycopg://"
    )


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
