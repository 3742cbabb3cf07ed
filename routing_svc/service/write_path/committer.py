"""The thread that commits the event loop's transactions, handed each commit directly.

The event loop stages a group's transaction itself and leaves only the commit
(SQLite's ``fsync``) to this thread, so that the disk's wait overlaps the
loop's work (see :mod:`routing_svc.service.write_path.group_commit`). The thread needs the
interpreter lock for a few microseconds of Python before SQLite releases it,
and CPython gives a waiting thread the lock only after the switch interval
(5 ms) or when its holder blocks; under load the event loop blocks only when it
runs out of requests to parse. So :meth:`Committer.hand_over` rings the thread
and then blocks the loop until the thread has started the commit (at most
:data:`COMMIT_HANDOFF_WAIT`), which hands it the lock at once.

The thread waits on a plain lock, not on an executor's queue: the loop rings it
and blocks straight away, so the thread usually wakes to a free interpreter
lock instead of waking once for the job and again for the lock, and a hand-over
builds no executor future.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections import deque
from collections.abc import Callable

from prometheus_client import Counter

COMMIT_HANDOFF_WAIT = 0.002
"""How long (seconds) the event loop waits at most for the committer to start a commit.

The wait is bounded, so a committer that is slow to be scheduled (or still busy)
costs the loop at most this long; the commit then starts when the thread gets
the interpreter lock, and nothing else changes.
"""

COMMIT_HANDOFF_TIMEOUTS = Counter(
    "routing_svc_commit_handoff_timeouts_total",
    "Commits whose thread had not started within COMMIT_HANDOFF_WAIT (the loop went on)",
)

_Job = tuple[Callable[[], None], threading.Lock, asyncio.AbstractEventLoop, "asyncio.Future[None]"]
"""``(commit, started, loop, done)``: ``started`` is released as the commit starts;
``done`` (a future of ``loop``) takes its outcome."""


class Committer:
    """One thread that runs commits in the order they are handed over.

    Parameters
    ----------
    name
        The thread's name.
    """

    def __init__(self, name: str) -> None:
        self._jobs: deque[_Job | None] = deque()  # ``None``: stop
        self._bell = threading.Lock()  # released to wake the thread
        self._bell.acquire()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    @property
    def thread_name(self) -> str:
        """The name of the thread that runs the commits."""
        return self._thread.name

    @property
    def waiting(self) -> int:
        """Commits handed over that the thread has not started yet (after :meth:`close`,
        the stop counts as one)."""
        return len(self._jobs)

    def hand_over(
        self, loop: asyncio.AbstractEventLoop, commit: Callable[[], None]
    ) -> asyncio.Future[None]:
        """Queue ``commit`` and block (at most :data:`COMMIT_HANDOFF_WAIT`) until the thread
        has started it; called on ``loop``'s thread.

        Returns
        -------
        asyncio.Future
            A future of ``loop`` that takes the commit's outcome (its exception, if it
            raised) once the commit has returned.
        """
        done: asyncio.Future[None] = loop.create_future()
        started = threading.Lock()
        started.acquire()
        self._jobs.append((commit, started, loop, done))
        self._ring()
        # blocking here hands the interpreter lock to the committer
        if not started.acquire(timeout=COMMIT_HANDOFF_WAIT):
            COMMIT_HANDOFF_TIMEOUTS.inc()
        return done

    def close(self) -> None:
        """Run what was handed over, then stop the thread."""
        self._jobs.append(None)
        self._ring()
        if self._thread is not threading.current_thread():
            self._thread.join()

    def _ring(self) -> None:
        # the bell may be open already (rung while the thread was busy): it then finds
        # the job as it looks for the next one
        with contextlib.suppress(RuntimeError):
            self._bell.release()

    def _run(self) -> None:
        while True:
            while not self._jobs:
                self._bell.acquire()
            job = self._jobs.popleft()
            if job is None:
                return
            commit, started, loop, done = job
            started.release()
            error: BaseException | None = None
            try:
                commit()
            except BaseException as exc:  # the loop's waiter gets it
                error = exc
            with contextlib.suppress(RuntimeError):  # a closed loop has no one waiting
                loop.call_soon_threadsafe(_settle, done, error)


def _settle(done: asyncio.Future[None], error: BaseException | None) -> None:
    """Set a commit's outcome on its future (one whose waiter went away takes none)."""
    if done.cancelled():
        return
    if error is not None:
        done.set_exception(error)
    else:
        done.set_result(None)
