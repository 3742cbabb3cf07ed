"""Checkpoints of a SQLite write-ahead log on a thread of their own.

By default SQLite checkpoints inside the ``COMMIT`` that takes the log past
1000 pages: that commit then also copies the pages into the database file and
waits for its ``fsync``, and every request of its group waits with it. The
store's connections therefore do not checkpoint
(``PRAGMA wal_autocheckpoint = 0``, see
:func:`routing_svc.store.engine.create_store_engine`); a :class:`WalCheckpointer`
runs passive checkpoints, which never block readers or writers, a few times a
second beside them. The log is restarted from its beginning by the first
write after a complete checkpoint, so it stays small under any load the
checkpoints keep up with. A process that stops without checkpointing leaves
nothing unsafe: SQLite checkpoints when the last connection closes, and
recovers the log on the next open.
"""

from __future__ import annotations

import sqlite3
import threading

__all__ = ["CHECKPOINT_INTERVAL_S", "WalCheckpointer"]

CHECKPOINT_INTERVAL_S = 0.25
"""Seconds between two passive checkpoints."""


class WalCheckpointer:
    """Run ``PRAGMA wal_checkpoint(PASSIVE)`` on ``path`` every ``interval`` seconds.

    Parameters
    ----------
    path
        The SQLite database file.
    interval
        Seconds between checkpoints.
    """

    def __init__(self, path: str, *, interval: float = CHECKPOINT_INTERVAL_S) -> None:
        self.path = path
        self.interval = interval
        self.checkpoints = 0
        """Passive checkpoints run so far."""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> WalCheckpointer:
        """Start the thread (once)."""
        if self._thread is None:
            self._thread = threading.Thread(
                target=self._run, name="routing-svc-wal-checkpoint", daemon=True
            )
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and wait for it."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def _run(self) -> None:
        connection = sqlite3.connect(self.path, isolation_level=None)
        try:
            while not self._stop.wait(self.interval):
                try:
                    connection.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchall()
                    self.checkpoints += 1
                except sqlite3.Error:
                    continue  # e.g. another checkpoint is running: try again later
        finally:
            connection.close()
