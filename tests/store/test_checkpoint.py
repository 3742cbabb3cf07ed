"""The write-ahead log is checkpointed by a thread of its own, not inside commits."""

from __future__ import annotations

import time
from pathlib import Path

from routing_svc.store import EventLog, FleetGroup, NewEvent
from routing_svc.store.checkpoint import WalCheckpointer


def fill(log: EventLog, fleet_id: str, groups: int) -> None:
    payload = '{"pad": "' + "x" * 2000 + '"}'
    version = 1
    for _ in range(groups):
        (items,) = log.append_groups(
            [
                FleetGroup(
                    fleet_id,
                    version,
                    ((None, None),),
                    lambda missed, fresh: [[NewEvent("t", payload, "{}")] * 10 for _ in fresh],
                )
            ]
        )
        version = items[0].version


def test_commits_do_not_checkpoint_and_the_thread_does(tmp_path: Path) -> None:
    """Events reach the database file (from the log) only through the checkpoint thread."""
    path = tmp_path / "events.db"
    with EventLog(f"sqlite:///{path}") as log:
        with log.engine.connect() as conn:
            assert conn.exec_driver_sql("PRAGMA wal_autocheckpoint").scalar_one() == 0
        checkpointer = log.checkpointer
        assert checkpointer is not None
        log.create_network("n", sha256="0" * 64, path="/dev/null", name="n")
        log.create_fleet("a", "n", "{}", "{}")
        checkpointer.stop()  # nothing checkpoints now
        before = path.stat().st_size
        fill(log, "a", 200)  # 2,000 events of 2 kB: past SQLite's automatic 1000 pages
        assert path.stat().st_size == before  # every commit left its pages in the log
        assert Path(f"{path}-wal").stat().st_size > 4_000_000
        restarted = WalCheckpointer(str(path), interval=0.05).start()
        try:
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline and path.stat().st_size < before + 4_000_000:
                time.sleep(0.05)
        finally:
            restarted.stop()
        assert path.stat().st_size > before + 4_000_000  # copied by the thread
        assert restarted.checkpoints >= 1
        assert [e.seq for e in log.events("a", after=2000, limit=10)] == [2001]
        assert log.integrity_check() == []
