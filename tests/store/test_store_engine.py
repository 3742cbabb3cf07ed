"""Durability settings, refusals and migrations of the store's engines."""

from __future__ import annotations

import sqlite3
import threading
from collections.abc import Callable
from pathlib import Path

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy.engine import make_url

from routing_svc.errors import StorageError
from routing_svc.store import EventLog, NewEvent, open_event_log
from routing_svc.store.engine import create_store_engine
from routing_svc.store.schema import metadata
from tests.helpers import append_one


def test_sqlite_connections_carry_the_durability_settings(tmp_path: Path) -> None:
    engine = create_store_engine(f"sqlite:///{tmp_path / 'e.db'}", busy_timeout_ms=1234)
    try:
        with engine.connect() as conn:
            pragma = {
                name: conn.exec_driver_sql(f"PRAGMA {name}").scalar_one()
                for name in ("journal_mode", "synchronous", "busy_timeout", "foreign_keys")
            }
    finally:
        engine.dispose()
    assert pragma == {
        "journal_mode": "wal",
        "synchronous": 2,
        "busy_timeout": 1234,
        "foreign_keys": 1,
    }


def test_sqlite_write_transactions_take_the_write_lock_at_begin(tmp_path: Path) -> None:
    path = tmp_path / "e.db"
    engine = create_store_engine(f"sqlite:///{path}", busy_timeout_ms=1000)
    other = sqlite3.connect(path, timeout=0, isolation_level=None)
    try:
        # nothing written yet, but BEGIN IMMEDIATE already holds the lock
        with engine.begin(), pytest.raises(sqlite3.OperationalError, match="locked"):
            other.execute("BEGIN IMMEDIATE")
        other.execute("BEGIN IMMEDIATE")  # free again after commit
        other.execute("ROLLBACK")
    finally:
        other.close()
        engine.dispose()


def test_sqlite_writer_waits_for_the_lock_instead_of_failing(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'e.db'}"
    with open_event_log(url) as log:
        log.create_network("n", sha256="0" * 64, path="/p", name="n")
        log.create_fleet("f", "n", "{}", "{}")
        holder = sqlite3.connect(tmp_path / "e.db", isolation_level=None)
        holder.execute("BEGIN IMMEDIATE")
        entered = threading.Event()
        results: list[int] = []

        def writer() -> None:
            entered.set()
            result = append_one(log, "f", expected_version=1, build=lambda m: [NewEvent("t", "{}")])
            results.append(result.version)

        thread = threading.Thread(target=writer)
        thread.start()
        entered.wait()
        thread.join(timeout=0.3)  # give the writer time to block on the lock
        holder.execute("COMMIT")
        holder.close()
        thread.join()
        assert results == [2]


def test_sqlite_lock_timeout_is_a_storage_error(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'e.db'}"
    with open_event_log(url, busy_timeout_ms=50) as log:
        log.create_network("n", sha256="0" * 64, path="/p", name="n")
        log.create_fleet("f", "n", "{}", "{}")
        holder = sqlite3.connect(tmp_path / "e.db", isolation_level=None)
        holder.execute("BEGIN IMMEDIATE")
        try:
            with pytest.raises(StorageError, match="locked"):
                append_one(log, "f", expected_version=1, build=lambda m: [NewEvent("t", "{}")])
        finally:
            holder.execute("ROLLBACK")
            holder.close()
        assert log.get_fleet("f").version == 1


def test_in_memory_sqlite_is_refused() -> None:
    with pytest.raises(StorageError, match="write-ahead"):
        EventLog("sqlite://").open()


def test_unsupported_backend_is_refused() -> None:
    with pytest.raises(StorageError, match="unsupported"):
        EventLog("mysql://user@localhost/db").open()


def test_missing_sqlite_directory_is_a_storage_error(tmp_path: Path) -> None:
    with pytest.raises(StorageError, match="open"):
        EventLog(f"sqlite:///{tmp_path / 'no' / 'such' / 'dir.db'}").open()


def test_postgresql_without_synchronous_commit_is_refused(
    pg_url_with: Callable[[str], str],
) -> None:
    with pytest.raises(StorageError, match="synchronous_commit=off"):
        EventLog(pg_url_with("-c synchronous_commit=off")).open()
    with open_event_log(pg_url_with("-c synchronous_commit=on")) as log:
        assert log.dialect == "postgresql"


def test_bare_postgresql_url_uses_psycopg(pg_url_with: Callable[[str], str]) -> None:
    url = make_url(pg_url_with("")).set(drivername="postgresql")
    with open_event_log(url.render_as_string(hide_password=False)) as log:
        assert log.list_networks() == []


def test_migrations_build_exactly_the_declared_schema(db_url: str) -> None:
    with open_event_log(db_url):
        pass
    engine = create_store_engine(db_url, busy_timeout_ms=1000)
    try:
        with engine.connect() as conn:
            diff = compare_metadata(MigrationContext.configure(conn), metadata)
            head = MigrationContext.configure(conn).get_current_revision()
    finally:
        engine.dispose()
    assert diff == []
    assert head == "0002"


def test_concurrent_opens_migrate_once(db_url: str) -> None:
    errors: list[BaseException] = []

    def opener() -> None:
        try:
            with open_event_log(db_url) as log:
                log.list_fleets()
        except BaseException as error:  # collected and asserted below
            errors.append(error)

    threads = [threading.Thread(target=opener) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []


def test_concurrent_first_opens_of_fresh_sqlite_files_all_succeed(tmp_path: Path) -> None:
    # switching a new file to WAL races between openers; none may see "database is locked"
    errors: list[BaseException] = []

    def opener(url: str) -> None:
        try:
            with open_event_log(url) as log:
                log.list_fleets()
        except BaseException as error:  # collected and asserted below
            errors.append(error)

    for attempt in range(30):
        url = f"sqlite:///{tmp_path / f'fresh-{attempt}.db'}"
        threads = [threading.Thread(target=opener, args=(url,)) for _ in range(4)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    assert errors == []
