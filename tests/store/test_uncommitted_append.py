"""``EventLog.try_append_groups_uncommitted``: an append that never waits for a lock, and
whose commit can run on another thread."""

from __future__ import annotations

import sqlite3
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from routing_svc.errors import RoutingSvcError, UnknownFleet
from routing_svc.store import EventLog, FleetGroup
from tests.helpers import one_each


@pytest.fixture
def sqlite_log(tmp_path: Path) -> Iterator[EventLog]:
    with EventLog(f"sqlite:///{tmp_path / 'events.db'}") as opened:
        opened.create_network("n", sha256="0" * 64, path="/dev/null", name="n")
        for fleet_id in ("a", "b"):
            opened.create_fleet(fleet_id, "n", "{}", "{}")
        yield opened


def groups(*fleets: str, version: int = 1) -> list[FleetGroup]:
    return [FleetGroup(f, version, ((None, None),), one_each) for f in fleets]


def database_file(log: EventLog) -> str:
    return log.url.removeprefix("sqlite:///")


def stored_seqs(log: EventLog, fleet_id: str) -> list[int]:
    return [e.seq for e in log.events(fleet_id)]


def test_commit_on_another_thread_makes_the_events_durable(sqlite_log: EventLog) -> None:
    opened = sqlite_log.try_append_groups_uncommitted(groups("a", "b"))
    assert opened is not None
    assert [[item.events[0].seq for item in items] for items in opened.items] == [[2], [2]]
    # not visible to readers before the commit
    assert stored_seqs(sqlite_log, "a") == [1]
    committer = threading.Thread(target=opened.commit)
    committer.start()
    committer.join()
    assert stored_seqs(sqlite_log, "a") == [1, 2]
    assert stored_seqs(sqlite_log, "b") == [1, 2]
    assert sqlite_log.get_fleet("a").version == 2
    # the next append starts from there, and the write lock was given back
    assert sqlite_log.append_groups(groups("a", version=2))[0][0].events[0].seq == 3
    assert sqlite_log.integrity_check() == []


def test_rollback_writes_nothing(sqlite_log: EventLog) -> None:
    opened = sqlite_log.try_append_groups_uncommitted(groups("a"))
    assert opened is not None
    opened.rollback()
    assert stored_seqs(sqlite_log, "a") == [1]
    assert sqlite_log.get_fleet("a").version == 1
    assert sqlite_log.append_groups(groups("a"))[0][0].events[0].seq == 2


def test_another_process_holding_the_write_lock_means_none_at_once(
    sqlite_log: EventLog,
) -> None:
    other = sqlite3.connect(database_file(sqlite_log), isolation_level=None)
    other.execute("BEGIN IMMEDIATE")
    try:
        assert sqlite_log.try_append_groups_uncommitted(groups("a")) is None
    finally:
        other.execute("ROLLBACK")
        other.close()
    # nothing was written, and the lock is free again for this process
    assert stored_seqs(sqlite_log, "a") == [1]
    opened = sqlite_log.try_append_groups_uncommitted(groups("a"))
    assert opened is not None
    opened.commit()
    assert stored_seqs(sqlite_log, "a") == [1, 2]


def test_writers_of_this_process_wait_for_the_open_transaction(sqlite_log: EventLog) -> None:
    opened = sqlite_log.try_append_groups_uncommitted(groups("a"))
    assert opened is not None
    # while it is open, another try gets None and a plain append waits
    assert sqlite_log.try_append_groups_uncommitted(groups("b")) is None
    done: list[int] = []
    writer = threading.Thread(
        target=lambda: done.append(sqlite_log.append_groups(groups("b"))[0][0].events[0].seq)
    )
    writer.start()
    writer.join(timeout=0.5)
    assert writer.is_alive() and done == []
    opened.commit()
    writer.join(timeout=60)
    assert done == [2]
    assert stored_seqs(sqlite_log, "a") == [1, 2]


def test_a_failing_append_rolls_back_and_frees_the_lock(sqlite_log: EventLog) -> None:
    with pytest.raises(UnknownFleet):
        sqlite_log.try_append_groups_uncommitted(groups("a", "nobody"))
    assert stored_seqs(sqlite_log, "a") == [1]
    assert sqlite_log.append_groups(groups("a"))[0][0].events[0].seq == 2


def test_the_pool_keeps_its_busy_timeout(sqlite_log: EventLog) -> None:
    """The append's own connection waits for nothing; the pooled ones still wait."""
    opened = sqlite_log.try_append_groups_uncommitted(groups("a"))
    assert opened is not None
    opened.commit()
    with sqlite_log.engine.connect() as conn:
        timeout = conn.exec_driver_sql("PRAGMA busy_timeout").scalar_one()
    assert timeout == sqlite_log.busy_timeout_ms


def test_postgresql_always_answers_none(pg_database: str, pg_schema: str) -> None:
    from tests.conftest import pg_url

    with EventLog(pg_url(pg_database, schema=pg_schema)) as log:
        log.create_network("n", sha256="0" * 64, path="/dev/null", name="n")
        log.create_fleet("a", "n", "{}", "{}")
        assert log.try_append_groups_uncommitted(groups("a")) is None
        assert [e.seq for e in log.events("a")] == [1]


def test_a_failing_commit_writes_nothing_and_frees_the_lock(sqlite_log: EventLog) -> None:
    """SQLite refuses the ``COMMIT`` (a deferred foreign key the transaction broke): the
    error is raised, nothing of the transaction is stored, and the next append works."""
    opened = sqlite_log.try_append_groups_uncommitted(groups("a"))
    assert opened is not None
    driver = opened.connection.connection.dbapi_connection
    assert driver is not None
    driver.execute("PRAGMA defer_foreign_keys = ON")
    driver.execute(
        "INSERT INTO events (fleet_id, seq, kind, payload, batch_size, created_at) "
        "VALUES ('nobody', 1, 'target', '{}', 1, '2026-01-01 00:00:00')"
    )
    with pytest.raises(RoutingSvcError, match="FOREIGN KEY"):
        opened.commit()
    assert stored_seqs(sqlite_log, "a") == [1]
    assert sqlite_log.get_fleet("a").version == 1
    again = sqlite_log.try_append_groups_uncommitted(groups("a"))
    assert again is not None
    again.commit()
    assert stored_seqs(sqlite_log, "a") == [1, 2]
    assert sqlite_log.integrity_check() == []
