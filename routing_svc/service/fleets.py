"""Fleet operations over the event log: the domain side of the REST API.

Reads are answered from a cached :class:`FleetRuntime` per fleet, caught up
with the log under the fleet's lock. Writes are computed as ``compute(runtime)
-> events`` and handed to the write path
(:class:`~routing_svc.service.write_path.GroupCommit`), which commits them in
groups and answers each with a
:data:`~routing_svc.service.write_path.PendingAnswer`.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import logging
import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import Future
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from routing_svc.errors import Conflict, UnknownFleet, UnknownNetwork
from routing_svc.service.background_solver import ConsolidationSolver
from routing_svc.service.canonical import dumps, dumps_finite
from routing_svc.service.creation import build_created_payload
from routing_svc.service.networks import NetworkEntry, NetworkRegistry
from routing_svc.service.runtime import FleetRuntime, same_snapshot
from routing_svc.service.schemas import FleetSpec, TargetSpec, VehicleStateChange
from routing_svc.service.vehicle_states import resolve_changes
from routing_svc.service.write_path import Answer, GroupCommit, PendingAnswer
from routing_svc.store import EventLog, EventRecord, NewEvent
from routing_svc.types import NetPosition

logger = logging.getLogger(__name__)


def request_hash(body: Any, *, finite: bool = False) -> str:
    """A digest of a request body, stored with its idempotency key: of its canonical
    text (:func:`dumps`; ``finite``: the body's floats are known finite, and the same
    text is written by :func:`dumps_finite`)."""
    text = dumps_finite(body) if finite else dumps(body)
    return hashlib.sha256(text.encode()).hexdigest()


class FleetService:
    """Fleets, targets and travel times, durable in an :class:`EventLog`."""

    def __init__(
        self,
        log: EventLog,
        networks: NetworkRegistry,
        *,
        recent_window: int,
        consolidation_workers: int = 0,
    ) -> None:
        self.log = log
        self.networks = networks
        self.recent_window = recent_window
        self.solver = (
            ConsolidationSolver(consolidation_workers) if consolidation_workers > 0 else None
        )
        """Where due consolidations are solved (``None``: on the write path)."""
        if self.solver is not None:
            try:  # in the background: the service serves meanwhile
                self.solver.start()
            except (RuntimeError, OSError):  # the first consolidation tries again
                logger.exception("the consolidation workers did not start")
        self._cache: dict[str, FleetRuntime] = {}
        self._locks: dict[str, threading.Lock] = {}
        self._locks_guard = threading.Lock()
        self._levels_seen: dict[str, dict[str, Any]] = {}
        self.group_commit = GroupCommit(log, self)
        """The write path every write of this service goes through."""

    # -- runtimes and locks -------------------------------------------------------

    def lock_of(self, fleet_id: str) -> threading.Lock:
        """The lock under which a fleet's runtime is read and changed."""
        with self._locks_guard:
            return self._locks.setdefault(fleet_id, threading.Lock())

    @contextmanager
    def _locked(self, fleet_id: str) -> Iterator[None]:
        with self.lock_of(fleet_id):
            yield

    def network(self, network_id: str) -> NetworkEntry:
        """A loaded network; one that another instance registered is loaded from its
        stored path when this host can read it (a shared ``--data-dir``)."""
        if network_id not in self.networks:
            record = self.log.get_network(network_id)
            path = Path(record.path)
            if not path.is_file():
                raise UnknownNetwork(
                    f"network {network_id!r} is registered, but its file {record.path!r} "
                    "is not readable on this instance (share --data-dir between instances)"
                )
            self.networks.load(record.id, path, name=record.name)
        return self.networks.get(network_id)

    def _load(self, fleet_id: str) -> FleetRuntime:
        """Build the runtime from the snapshot and the events after it."""
        record = self.log.get_fleet(fleet_id)
        entry = self.network(record.network_id)
        first = self.log.events(fleet_id, after=0, limit=1)[0]
        runtime = FleetRuntime(
            fleet_id,
            entry,
            json.loads(first.payload_json),
            recent_window=self.recent_window,
            solver=self.solver,
        )
        if (
            record.state_json is not None
            and record.snapshot_version is not None
            and not runtime.restore(record.state_json)
        ):  # a snapshot older than service levels: replay the fleet from its start
            runtime = FleetRuntime(
                fleet_id,
                entry,
                json.loads(first.payload_json),
                recent_window=self.recent_window,
                solver=self.solver,
            )
        self.catch_up(runtime, self.log.events_since(fleet_id, runtime.version))
        return runtime

    @staticmethod
    def catch_up(runtime: FleetRuntime, events: Sequence[EventRecord]) -> None:
        """Replay the ``events`` after the runtime's version."""
        for event in events:
            if event.seq > runtime.version:
                runtime.replay(event.seq, event.kind, event.payload_json, event.result_json)

    def _runtime(self, fleet_id: str, *, fresh: bool = True) -> FleetRuntime:
        """The cached runtime, caught up with the log when ``fresh``."""
        runtime = self._cache.get(fleet_id)
        if runtime is None:
            runtime = self._load(fleet_id)
            self._cache[fleet_id] = runtime
        elif fresh:
            record = self.log.get_fleet(fleet_id)
            if record.version > runtime.version:
                self.catch_up(runtime, self.log.events_since(fleet_id, runtime.version))
        if runtime.deleted:
            raise UnknownFleet(f"no fleet {fleet_id!r}")
        return runtime

    def is_cached(self, fleet_id: str) -> bool:
        """Whether the fleet's runtime is in memory (a write then needs no database read
        before it joins the queue)."""
        runtime = self._cache.get(fleet_id)
        return runtime is not None and not runtime.deleted

    def consolidation_wait(self, fleet_id: str, targets_ahead: int) -> Future[Any] | None:
        """The solve the fleet's next ``targets_ahead`` targets would wait for, if its
        runtime is in memory (:meth:`FleetRuntime.consolidation_wait`)."""
        runtime = self._cache.get(fleet_id)
        return None if runtime is None else runtime.consolidation_wait(targets_ahead)

    def solves_within(self, fleet_id: str, targets_ahead: int) -> bool:
        """Whether the fleet's next ``targets_ahead`` targets could wait for a solve
        (:meth:`FleetRuntime.solves_within`); called under its lock."""
        runtime = self._cache.get(fleet_id)
        return runtime is not None and runtime.solves_within(targets_ahead)

    def runtime_for_write(self, fleet_id: str) -> FleetRuntime:
        """The fleet's runtime, loaded if it is not in memory, not caught up with the
        log (the append hands over what it missed); called under its lock."""
        return self._runtime(fleet_id, fresh=False)

    def forget(self, fleet_id: str) -> None:
        """Drop a runtime that may have diverged from the log; it is rebuilt from it."""
        self._cache.pop(fleet_id, None)

    # -- the write path -----------------------------------------------------------

    async def settled(self, answer: PendingAnswer, *, deadline: float | None) -> Answer:
        """Wait for a write's answer until ``deadline`` (:meth:`GroupCommit.settled`)."""
        return await self.group_commit.settled(answer, deadline=deadline)

    async def drain(self) -> None:
        """Wait until the event loop's writes are committed (:meth:`GroupCommit.drain`)."""
        await self.group_commit.drain()

    def close(self) -> None:
        """Commit the queued writes and stop the writers (:meth:`GroupCommit.close`)."""
        self.group_commit.close()
        if self.solver is not None:
            self.solver.close()

    # -- fleets -----------------------------------------------------------------

    def create_fleet(self, spec: FleetSpec) -> dict[str, Any]:
        entry = self.network(spec.network)
        return self.commit_fleet(spec, entry, build_created_payload(spec, entry))

    def commit_fleet(
        self, spec: FleetSpec, entry: NetworkEntry, created: dict[str, Any]
    ) -> dict[str, Any]:
        """Store a fleet whose creation payload (:func:`build_created_payload`) is solved."""
        runtime = FleetRuntime(
            spec.id, entry, created, recent_window=self.recent_window, solver=self.solver
        )
        self.log.create_fleet(spec.id, entry.id, dumps(created["config"]), dumps(created))
        with self._locked(spec.id):
            self._cache[spec.id] = runtime
        return runtime.describe()

    def get_fleet(self, fleet_id: str) -> dict[str, Any]:
        with self._locked(fleet_id):
            return self._runtime(fleet_id).describe()

    def list_fleets(self) -> list[dict[str, Any]]:
        out = []
        for record in self.log.list_fleets():
            try:
                out.append(self.get_fleet(record.id))
            except UnknownFleet:
                continue
        return out

    def delete_fleet(self, fleet_id: str) -> None:
        with self._locked(fleet_id):
            self._runtime(fleet_id)
            self.log.delete_fleet(fleet_id)
            self._cache.pop(fleet_id, None)

    def metrics(self, fleet_id: str) -> dict[str, Any]:
        with self._locked(fleet_id):
            return self._runtime(fleet_id).metrics()

    def cached_service_levels(self) -> list[tuple[str, dict[str, Any]]]:
        """``(fleet id, service levels)`` of every fleet in memory (no database read).

        A fleet's lock is only tried, never waited for: the event loop may hold it
        across an ``await`` (its writer, :class:`GroupCommit`), and a scrape runs on
        that loop.
        A fleet whose lock is taken reports what it reported last.
        """
        out = []
        for fleet_id in sorted(self._cache):
            lock = self.lock_of(fleet_id)
            if lock.acquire(blocking=False):
                try:
                    runtime = self._cache.get(fleet_id)
                    if runtime is None or runtime.deleted:
                        self._levels_seen.pop(fleet_id, None)
                    else:
                        self._levels_seen[fleet_id] = runtime.levels.report()
                finally:
                    lock.release()
            if fleet_id in self._levels_seen:
                out.append((fleet_id, self._levels_seen[fleet_id]))
        return out

    def events(self, fleet_id: str, *, after: int, limit: int) -> list[dict[str, Any]]:
        return [
            {
                "seq": e.seq,
                "kind": e.kind,
                "payload": json.loads(e.payload_json),
                "result": None if e.result_json is None else json.loads(e.result_json),
                "created_at": e.created_at.isoformat(),
            }
            for e in self.log.events(fleet_id, after=after, limit=limit)
        ]

    # -- targets ----------------------------------------------------------------

    def network_of(self, fleet_id: str) -> NetworkEntry:
        """The network a fleet lives on."""
        cached = self._cache.get(fleet_id)  # a fleet's network never changes: no lock
        if cached is not None and not cached.deleted:
            return cached.entry
        with self._locked(fleet_id):
            return self._runtime(fleet_id, fresh=False).entry

    def _resolve_targets(
        self, fleet_id: str, targets: Sequence[TargetSpec]
    ) -> list[tuple[NetPosition, list[str] | None]]:
        entry = self.network_of(fleet_id)
        return [
            (entry.resolve(t.position), list(t.requires) if t.requires else None) for t in targets
        ]

    def submit_targets(
        self,
        fleet_id: str,
        targets: Sequence[TargetSpec],
        *,
        idempotency_key: str | None = None,
        body: Any = None,
        loop: asyncio.AbstractEventLoop | None = None,
    ) -> PendingAnswer:
        """Queue targets to be applied in order in one transaction (see
        :meth:`GroupCommit.submit`, also for ``loop``).

        Positions are resolved first, so a bad position fails here and queues nothing.
        """
        return self.submit_resolved(
            fleet_id,
            self._resolve_targets(fleet_id, targets),
            idempotency_key=idempotency_key,
            body=body,
            loop=loop,
        )

    def submit_resolved(
        self,
        fleet_id: str,
        resolved: Sequence[tuple[NetPosition, list[str] | None]],
        *,
        idempotency_key: str | None = None,
        body: Any = None,
        loop: asyncio.AbstractEventLoop | None = None,
    ) -> PendingAnswer:
        """:meth:`submit_targets` for targets already resolved on the fleet's network
        (``body``, the request the key's digest is taken over, as the route has it: its
        positions validated, so its floats are finite)."""

        def compute(runtime: FleetRuntime) -> list[NewEvent]:
            out = []
            described = runtime.entry.describe_many([position for position, _ in resolved])
            for (position, requires), place in zip(resolved, described, strict=True):
                payload, result = runtime.apply_target(position, requires, described=place)
                out.append(NewEvent("target", payload, result))
            return out

        digest = request_hash(body, finite=True) if idempotency_key is not None else None
        return self.group_commit.submit(
            fleet_id,
            compute,
            idempotency_key=idempotency_key,
            digest=digest,
            size=len(resolved),
            loop=loop,
        )

    def post_targets(
        self,
        fleet_id: str,
        targets: Sequence[TargetSpec],
        *,
        idempotency_key: str | None = None,
        body: Any = None,
    ) -> tuple[list[str], int]:
        """Apply targets in order in one transaction; return each result's JSON text."""
        return self.submit_targets(
            fleet_id, targets, idempotency_key=idempotency_key, body=body
        ).result()

    def assign(self, fleet_id: str, target: TargetSpec) -> dict[str, Any]:
        """Who would go now (``dispatch``) and whose reference would move (``moved``,
        from the closest references ``served_by``); changes nothing."""
        ((position, requires),) = self._resolve_targets(fleet_id, [target])
        with self._locked(fleet_id):
            runtime = self._runtime(fleet_id)
            d = runtime.fleet.assign(position, requires)
            assert d.sent is not None
            return {
                "version": runtime.version,
                "target": runtime.entry.describe(position),
                "requires": requires,
                "dispatch": d.sent.to_dict(),
                "served_by": list(d.served_by),
                "times": list(d.times),
                "moved": d.moved,
                "cost": d.cost,
                "objective": d.objective,
            }

    def posts(self, fleet_id: str) -> dict[str, Any]:
        """Where each available vehicle should wait now (:meth:`Fleet.posts`); changes
        nothing."""
        with self._locked(fleet_id):
            runtime = self._runtime(fleet_id)
            fleet = runtime.fleet
            ids = [v.id for v in fleet.vehicles]
            return {
                "version": runtime.version,
                "posts": [
                    {
                        "vehicle": ids[post.vehicle],
                        "position": runtime.entry.describe(post.position),
                        "reference_of": ids[post.reference_of],
                        "time": post.time,
                    }
                    for post in fleet.posts()
                ],
            }

    def submit_vehicle_states(
        self,
        fleet_id: str,
        changes: Sequence[VehicleStateChange],
        *,
        idempotency_key: str | None = None,
        body: Any = None,
    ) -> PendingAnswer:
        """Queue vehicles' new live states, one ``vehicle_state`` event, all or none.

        Positions are resolved first, so a position off the network fails here
        and queues nothing; an unknown vehicle or a timestamp that goes back in
        time fails the request when it is applied, before anything changed.
        """
        with self._locked(fleet_id):
            entry = self._runtime(fleet_id, fresh=False).entry
        resolved = [(c, None if c.position is None else entry.resolve(c.position)) for c in changes]

        def compute(runtime: FleetRuntime) -> list[NewEvent]:
            payload, result = runtime.apply_vehicle_states(resolve_changes(runtime, resolved))
            return [NewEvent("vehicle_state", payload, result)]

        digest = request_hash(body) if idempotency_key is not None else None
        return self.group_commit.submit(
            fleet_id, compute, idempotency_key=idempotency_key, digest=digest
        )

    def put_vehicle_states(
        self,
        fleet_id: str,
        changes: Sequence[VehicleStateChange],
        *,
        idempotency_key: str | None = None,
        body: Any = None,
    ) -> dict[str, Any]:
        """Apply :meth:`submit_vehicle_states` and wait for its commit; the event's result."""
        results, _ = self.submit_vehicle_states(
            fleet_id, changes, idempotency_key=idempotency_key, body=body
        ).result()
        data: dict[str, Any] = json.loads(results[0])
        return data

    def put_travel_times(self, fleet_id: str, times: dict[str, float]) -> dict[str, Any]:
        with self._locked(fleet_id):
            runtime = self._runtime(fleet_id, fresh=False)
            if runtime.cost_kind != "time":
                raise Conflict(
                    "this fleet uses length costs; travel times apply to cost='time' fleets"
                )
            runtime.base_space.with_travel_times(times)  # validates before anything is written

        def compute(runtime: FleetRuntime) -> list[NewEvent]:
            payload, result = runtime.apply_travel_times(times)
            return [NewEvent("weights_updated", payload, result)]

        results, _ = self.group_commit.submit(fleet_id, compute).result()
        data: dict[str, Any] = json.loads(results[0])
        return data

    # -- replay -----------------------------------------------------------------

    def verify(self, fleet_id: str) -> dict[str, Any]:
        """Rebuild the fleet from its whole log and compare with the stored snapshot."""
        from routing_svc.errors import ReplayMismatch

        record = self.log.get_fleet(fleet_id, include_deleted=True)
        entry = self.network(record.network_id)
        events = self.log.events_since(fleet_id, 0)
        runtime = FleetRuntime(
            fleet_id,
            entry,
            json.loads(events[0].payload_json),
            recent_window=self.recent_window,
            solver=self.solver,
        )
        identical = None
        at = record.snapshot_version
        if record.state_json is not None and at is not None:
            self.catch_up(runtime, [e for e in events[1:] if e.seq <= at])
            identical = same_snapshot(runtime.snapshot_json(), record.state_json)
            if not identical:
                raise ReplayMismatch(
                    f"fleet {fleet_id!r}: the replayed state at version {at} differs from the "
                    "stored snapshot"
                )
        self.catch_up(runtime, events[1:])
        if runtime.version != record.version:
            raise ReplayMismatch(
                f"replay reached version {runtime.version}, stored {record.version}"
            )
        return {
            "fleet": fleet_id,
            "version": runtime.version,
            "events": len(events),
            "snapshot_version": at,
            "snapshot_identical": identical,
            "state_sha256": hashlib.sha256(runtime.snapshot_json().encode()).hexdigest(),
        }
