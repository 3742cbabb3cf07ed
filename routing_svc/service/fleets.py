"""Fleet operations over the event log: the domain side of the REST API.

Every write goes through :meth:`EventLog.append`: under the fleet's lock the
cached :class:`FleetRuntime` first replays the events other workers (or hosts)
wrote since it last looked, then computes the new events; the answer is
returned only after the transaction committed. A cache that may have diverged
(an append that failed after computing) is dropped and rebuilt from the log.
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from routing_svc.errors import Conflict, UnknownFleet
from routing_svc.service.creation import build_created_payload
from routing_svc.service.networks import NetworkRegistry
from routing_svc.service.runtime import FleetRuntime, dumps
from routing_svc.service.schemas import FleetSpec, TargetSpec
from routing_svc.store import EventLog, EventRecord, NewEvent
from routing_svc.types import NetPosition

SNAPSHOT_EVERY = 64
"""A snapshot of the state is stored whenever the version crosses a multiple of this."""


def request_hash(body: Any) -> str:
    """A digest of a request body, stored with its idempotency key."""
    return hashlib.sha256(dumps(body).encode()).hexdigest()


class FleetService:
    """Fleets, targets and travel times, durable in an :class:`EventLog`."""

    def __init__(self, log: EventLog, networks: NetworkRegistry, *, recent_window: int) -> None:
        self.log = log
        self.networks = networks
        self.recent_window = recent_window
        self._cache: dict[str, FleetRuntime] = {}
        self._locks: dict[str, threading.Lock] = {}
        self._locks_guard = threading.Lock()

    # -- plumbing ---------------------------------------------------------------

    @contextmanager
    def _locked(self, fleet_id: str) -> Iterator[None]:
        with self._locks_guard:
            lock = self._locks.setdefault(fleet_id, threading.Lock())
        with lock:
            yield

    def _load(self, fleet_id: str) -> FleetRuntime:
        """Build the runtime from the snapshot and the events after it."""
        record = self.log.get_fleet(fleet_id)
        entry = self.networks.get(record.network_id)
        first = self.log.events(fleet_id, after=0, limit=1)[0]
        runtime = FleetRuntime(
            fleet_id, entry, json.loads(first.payload_json), recent_window=self.recent_window
        )
        if record.state_json is not None and record.snapshot_version is not None:
            runtime.restore(record.state_json)
        self._replay(runtime, self.log.events_since(fleet_id, runtime.version))
        return runtime

    @staticmethod
    def _replay(runtime: FleetRuntime, events: Sequence[EventRecord]) -> None:
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
                self._replay(runtime, self.log.events_since(fleet_id, runtime.version))
        if runtime.deleted:
            raise UnknownFleet(f"no fleet {fleet_id!r}")
        return runtime

    def _append(
        self,
        fleet_id: str,
        compute: Any,
        *,
        idempotency_key: str | None = None,
        digest: str | None = None,
    ) -> tuple[list[str], int]:
        """Run ``compute(runtime) -> [NewEvent]`` under the log's lock; return results."""
        with self._locked(fleet_id):
            runtime = self._runtime(fleet_id, fresh=False)

            before = [runtime.version]

            def build(missed: list[EventRecord]) -> list[NewEvent]:
                self._replay(runtime, missed)
                before[0] = runtime.version
                events: list[NewEvent] = compute(runtime)
                return events

            def snapshot(version: int) -> str | None:
                due = version // SNAPSHOT_EVERY != before[0] // SNAPSHOT_EVERY
                return runtime.snapshot_json() if due else None

            try:
                result = self.log.append(
                    fleet_id,
                    expected_version=runtime.version,
                    build=build,
                    idempotency_key=idempotency_key,
                    request_hash=digest,
                    snapshot=snapshot,
                )
            except BaseException:
                self._cache.pop(fleet_id, None)
                raise
            if result.duplicate:
                self._replay(runtime, result.missed)
            last = result.events[-1].seq if result.events else result.version
            return [e.result_json or "{}" for e in result.events], last

    # -- fleets -----------------------------------------------------------------

    def create_fleet(self, spec: FleetSpec) -> dict[str, Any]:
        entry = self.networks.get(spec.network)
        created = build_created_payload(spec, entry)
        runtime = FleetRuntime(spec.id, entry, created, recent_window=self.recent_window)
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

    def events(self, fleet_id: str, *, after: int, limit: int) -> list[dict[str, Any]]:
        self._runtime(fleet_id, fresh=False) if fleet_id in self._cache else None
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

    def _resolve_targets(
        self, fleet_id: str, targets: Sequence[TargetSpec]
    ) -> list[tuple[NetPosition, list[str] | None]]:
        with self._locked(fleet_id):
            entry = self._runtime(fleet_id, fresh=False).entry
        return [
            (entry.resolve(t.position), list(t.requires) if t.requires else None) for t in targets
        ]

    def post_targets(
        self,
        fleet_id: str,
        targets: Sequence[TargetSpec],
        *,
        idempotency_key: str | None = None,
        body: Any = None,
    ) -> tuple[list[str], int]:
        """Apply targets in order in one transaction; return each result's JSON text."""
        resolved = self._resolve_targets(fleet_id, targets)

        def compute(runtime: FleetRuntime) -> list[NewEvent]:
            out = []
            for position, requires in resolved:
                payload, result = runtime.apply_target(position, requires)
                out.append(NewEvent("target", payload, result))
            return out

        digest = request_hash(body) if idempotency_key is not None else None
        return self._append(fleet_id, compute, idempotency_key=idempotency_key, digest=digest)

    def assign(self, fleet_id: str, target: TargetSpec) -> dict[str, Any]:
        ((position, requires),) = self._resolve_targets(fleet_id, [target])
        with self._locked(fleet_id):
            runtime = self._runtime(fleet_id)
            d = runtime.fleet.assign(position, requires)
            return {
                "version": runtime.version,
                "target": runtime.entry.describe(position),
                "requires": requires,
                "served_by": list(d.served_by),
                "times": list(d.times),
                "moved": d.moved,
                "cost": d.cost,
                "objective": d.objective,
            }

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

        results, _ = self._append(fleet_id, compute)
        data: dict[str, Any] = json.loads(results[0])
        return data

    # -- replay -----------------------------------------------------------------

    def verify(self, fleet_id: str) -> dict[str, Any]:
        """Rebuild the fleet from its whole log and compare with the stored snapshot."""
        from routing_svc.errors import ReplayMismatch

        record = self.log.get_fleet(fleet_id, include_deleted=True)
        entry = self.networks.get(record.network_id)
        events = self.log.events_since(fleet_id, 0)
        runtime = FleetRuntime(
            fleet_id, entry, json.loads(events[0].payload_json), recent_window=self.recent_window
        )
        identical = None
        at = record.snapshot_version
        if record.state_json is not None and at is not None:
            self._replay(runtime, [e for e in events[1:] if e.seq <= at])
            identical = runtime.snapshot_json() == record.state_json
            if not identical:
                raise ReplayMismatch(
                    f"fleet {fleet_id!r}: the replayed state at version {at} differs from the "
                    "stored snapshot"
                )
        self._replay(runtime, events[1:])
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
