"""Consolidations solved in worker processes, off the write path.

A ``consolidating`` fleet's due consolidation (a p-median of its reservoir, solved
once per fold and once on the whole, :func:`routing_svc.sa.consolidation.consolidate`)
takes up to seconds. Solved inside the target that made it due, it would hold that
target's answer and every write queued behind it. The service hands it instead to a
worker process (:meth:`ConsolidationSolver.submit`) and keeps serving with the
references it has; the first target of the fleet after the solve finished applies
it, if it is still the due one, and that target's event records it, so that replay
applies it at the same place without solving (:mod:`routing_svc.service.runtime`).
Targets that come faster than it is solved wait for it once the period that follows it
has passed (:meth:`~routing_svc.sa.consolidation.ConsolidationPolicy.apply_by`), so
that a burst of targets does not outrun the schedule, and for the epoch's first at once
(a small reservoir: a batch of a few hundred targets does not leave a new fleet where it
started); the write path keeps such a fleet's writes queued meanwhile
(:meth:`PendingConsolidation.holds`) and goes on with the other fleets'.

Processes, not threads: much of the solve (the Python around the compiled shortest paths
and interchange, whose kernels alone release the GIL) holds the GIL, and a thread would
stall the write path almost as much as solving inline.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np

from routing_svc.sa.consolidation import Consolidation, ConsolidationJob, ConsolidationKey
from routing_svc.sa.interchange import fast_interchange, greedy, neighbourhood_search
from routing_svc.sa.space import P

T = TypeVar("T")

logger = logging.getLogger(__name__)

PARENT_CHECK_S = 1.0
"""How often a worker checks that its service process is still there."""

LONGEST_WAIT_S = 120.0
"""How long a target waits for a consolidation it must apply before solving it itself."""


def _solve(job: ConsolidationJob[P]) -> Consolidation[P]:
    return job.solve()


def _ready() -> bool:
    """Load what a solve runs (the package, the compiled kernels from their cache) in a
    worker that has just started."""
    costs = np.array([[0.0, 2.0, 1.0], [2.0, 0.0, 1.0], [1.0, 1.0, 0.0]])
    weights = np.ones(3)
    sites = neighbourhood_search(
        costs, weights, fast_interchange(costs, weights, greedy(costs, weights, 2))
    )
    return bool(sites.size == 2)


def _exit_with(parent: int) -> None:
    """Run in each worker: the service's own signals (Ctrl-C or ``SIGTERM`` to its process
    group) are left to the service, which stops its workers when it shuts down; and the
    worker leaves as soon as the service process is gone (a ``kill -9`` gives it no other
    sign), so that no worker outlives its service."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_S)
        os._exit(0)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


class ConsolidationSolver:
    """Worker processes that solve consolidation jobs, started by :meth:`start` or on
    the first job.

    Parameters
    ----------
    workers : int
        Processes (at least 1).
    """

    def __init__(self, workers: int = 1) -> None:
        if workers < 1:
            raise ValueError("a consolidation solver needs at least one worker")
        self.workers = workers
        self._pool: ProcessPoolExecutor | None = None
        self._guard = threading.Lock()
        self._solving = False
        """Whether a job was submitted since the pool started (:meth:`close` waits)."""
        self._loading: list[Future[bool]] = []
        """The workers' loads that :meth:`start` submitted."""

    def start(self) -> list[Future[bool]]:
        """Start the workers now, each loading what a solve runs, so that the first
        consolidation after the service starts does not wait for a process to start and
        import the package (the service calls this at start-up)."""
        loading = [self._submitted(_ready, solving=False) for _ in range(self.workers)]
        with self._guard:
            self._loading = loading
        return loading

    def submit(self, job: ConsolidationJob[P]) -> Future[Consolidation[P]]:
        """Solve ``job`` in a worker; a pool whose worker died is started again."""
        return self._submitted(_solve, job, solving=True)

    def _submitted(self, work: Callable[..., T], *args: object, solving: bool) -> Future[T]:
        with self._guard:
            self._solving = self._solving or solving
            for _ in range(2):
                if self._pool is None:
                    self._pool = ProcessPoolExecutor(
                        self.workers,
                        mp_context=multiprocessing.get_context("spawn"),
                        initializer=_exit_with,
                        initargs=(os.getpid(),),
                    )
                try:
                    return self._pool.submit(work, *args)
                except BrokenProcessPool:
                    self._pool.shutdown(wait=False, cancel_futures=True)
                    self._pool = None
            raise RuntimeError("the consolidation workers cannot be started")

    def close(self) -> None:
        """Stop the workers; jobs not finished are dropped (their fleets are still due,
        and solve again when the service comes back). Workers still loading (:meth:`start`)
        are not waited for: they leave once loaded. Idle workers are waited for, so that
        the pool's queues are released before the process ends."""
        with self._guard:
            if self._pool is not None:
                idle = all(f.done() for f in self._loading)
                self._pool.shutdown(wait=self._solving or idle, cancel_futures=True)
                self._pool = None
                self._solving = False
                self._loading = []


@dataclass(frozen=True, slots=True)
class PendingConsolidation(Generic[P]):
    """A job handed to the solver and its future answer."""

    job: ConsolidationJob[P]
    answer: Future[Consolidation[P]]
    submitted: float = field(default_factory=time.monotonic)

    @property
    def key(self) -> ConsolidationKey:
        return self.job.key

    def holds(self, targets: int) -> bool:
        """Whether a target that comes when the fleet has seen ``targets`` would wait for
        this solve (:meth:`solved`): it is not finished, ``targets >= job.apply_by``, and
        it has run less than :data:`LONGEST_WAIT_S`. The write path then leaves the
        fleet's writes queued, and serves the other fleets meanwhile."""
        return (
            targets >= self.job.apply_by
            and not self.answer.done()
            and time.monotonic() - self.submitted < LONGEST_WAIT_S
        )

    def solved(self, targets: int) -> tuple[ConsolidationKey, Consolidation[P]] | None:
        """The answer when it is ready (``None`` before), waited for once the fleet has
        seen ``targets >= job.apply_by``. A solve that failed in the worker, or takes
        longer than :data:`LONGEST_WAIT_S` then, is solved here, so that it fails, if it
        must, as it would inline."""
        if not self.answer.done() and targets < self.job.apply_by:
            return None
        try:
            return self.key, self.answer.result(timeout=LONGEST_WAIT_S)
        except Exception:
            logger.exception("a consolidation failed in its worker; solving it on the write path")
            return self.key, self.job.solve()
