"""A fleet as a replayable state machine over its event log.

Events (each with a per-fleet ``seq``; the fleet's ``version`` is the number of
applied events):

- ``fleet_created`` (seq 1): network, cost, config, vehicles with their
  starting positions, the optional reference demand and its optimum;
- ``target``: a snapped target position and its required types; the result is
  the answer the client got (:meth:`FleetRuntime.apply_target`: the dispatch
  answer, who goes now, and the learning step, whose reference moved), with the
  consolidation the target applied, if any (``consolidating`` fleets; solved in a
  worker since the target that made it due, :mod:`routing_svc.service.background_solver`,
  or inside the target without one), which replay applies as recorded instead of
  solving it again;
- ``weights_updated``: per-edge travel times (traffic-driven costs);
- ``vehicle_state``: vehicles' new live states (status, current position or
  ``null`` for "at its reference", timestamp), applied all or none;
- ``fleet_deleted``.

Applying the same events in the same order gives bit-identical state: every
input is stored already snapped, results are plain JSON with exact float
round trips, and the only randomness (annealing) derives from the seed.
"""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Sequence
from concurrent.futures import Future
from typing import Any

from routing_svc.demand import DemandDistribution
from routing_svc.errors import Conflict, InvalidInput, ReplayMismatch
from routing_svc.network import RoadSpace
from routing_svc.optimum import gap
from routing_svc.sa import Consolidation, Fleet, FleetConfig, Vehicle
from routing_svc.sa.live import Status, VehicleState
from routing_svc.service.background_solver import (
    ConsolidationSolver,
    PendingConsolidation,
)
from routing_svc.service.canonical import (
    TargetResult,
    dumps,
    same_state,
    state_dumps,
    target_payload,
)
from routing_svc.service.networks import NetworkEntry
from routing_svc.service.reference import build_demand, expected_cost_now
from routing_svc.service.service_levels import DEFAULT_THRESHOLDS, ServiceLevels
from routing_svc.types import NetPosition

SNAPSHOT_POSITIONS = 512
"""Positions a snapshot holds at the base cadence (:meth:`FleetRuntime.snapshot_every`)."""


class FleetRuntime:
    """The in-memory state of one fleet, advanced only by events."""

    def __init__(
        self,
        fleet_id: str,
        entry: NetworkEntry,
        created: dict[str, Any],
        *,
        recent_window: int,
        solver: ConsolidationSolver | None = None,
    ) -> None:
        self.id = fleet_id
        self.entry = entry
        self.created = created
        self.cost_kind: str = created["cost"]
        self.base_space: RoadSpace = entry.space(self.cost_kind)
        self.travel_times: dict[str, float] = {}
        vehicles = [
            (
                Vehicle(v["id"], v["type"], float(v["speed"])),
                self.base_space.decode(v["position"]),
            )
            for v in created["vehicles"]
        ]
        self.fleet: Fleet[NetPosition] = Fleet.create(
            self.base_space,
            vehicles,
            FleetConfig.from_dict(created["config"], self.base_space.decode),
        )
        self._solver = solver
        self._pending: PendingConsolidation[NetPosition] | None = None
        self.fleet.defer_consolidations = solver is not None
        self.version = 1
        self.deleted = False
        self.cost_sum = 0.0
        self.recent: deque[float] = deque(maxlen=recent_window)
        self.levels = ServiceLevels(
            created.get("service_thresholds", DEFAULT_THRESHOLDS), window=recent_window
        )
        self.reference: dict[str, Any] | None = created.get("reference")
        self._reference_distribution: DemandDistribution[NetPosition] | None = None

    # -- events -----------------------------------------------------------------

    def apply_target(
        self,
        target: NetPosition,
        requires: Sequence[str] | None,
        *,
        recorded: Consolidation[NetPosition] | None = None,
        recorded_for: Sequence[str] | None = None,
        replaying: bool = False,
        legacy: bool = False,
        described: dict[str, Any] | None = None,
    ) -> tuple[str, str]:
        """Serve one target; return the event's payload and result JSON.

        ``replaying``: the event is read back from the log, and ``recorded`` is the
        consolidation its stored result holds (applied, not solved again), for the
        vehicles ``recorded_for`` when it names them.
        ``legacy``: the stored result predates the dispatch answer; it is written
        again without it. ``described``: the target's description, computed already
        (:meth:`NetworkEntry.describe_many`).
        """
        self._check_live()
        if replaying:
            outcome = self.fleet.replay_observe(target, requires, recorded, recorded_for)
        else:
            self._hand_over_due()  # one that fell due in events caught up from the log
            pending = self._pending
            solved = None if pending is None else pending.solved(self.fleet.state.targets)
            outcome = self.fleet.observe(target, requires, solved=solved)
            self._hand_over_due()
        seq = self.version + 1
        d = outcome.dispatch
        if described is None:
            described = self.entry.describe(target)
        required = list(requires) if requires else None
        result = TargetResult(
            seq=seq,
            target=described,
            requires=required,
            served_by=d.served_by,
            times=d.times,
            moved=d.moved,
            cost=d.cost,
            objective=d.objective,
            step_size=outcome.step_size,
            moved_by=outcome.moved_by,
            noise=outcome.noise,
            new_position=(
                described
                if outcome.new_position is target
                else self.entry.describe(outcome.new_position)
            ),
            backed_off=[
                (self.fleet.vehicles[j].id, self.entry.describe(p)) for j, p in outcome.backed_off
            ],
            consolidated=None
            if outcome.consolidation is None
            else {
                **outcome.consolidation.to_dict(self.base_space.encode),
                **({"vehicles": list(outcome.consolidated)} if self.fleet.learns_per_type else {}),
            },
            dispatch=None if legacy or d.sent is None else d.sent.to_dict(),
        ).to_json()
        payload = target_payload(self.base_space.encode(target), required)
        self.version = seq
        self.cost_sum += d.cost
        self.recent.append(d.cost)
        self.levels.record(d.cost if d.sent is None else d.sent.completion)
        return payload, result

    def consolidation_wait(self, targets_ahead: int) -> Future[Any] | None:
        """The solve that the fleet's next ``targets_ahead`` targets could wait for
        (:meth:`PendingConsolidation.holds`; the last of them comes when the fleet has seen
        ``targets_ahead - 1`` more), else ``None``."""
        pending = self._pending
        if pending is None or not pending.holds(self._seen_by_last(targets_ahead)):
            return None
        return pending.answer

    def _seen_by_last(self, targets_ahead: int) -> int:
        """Targets the fleet has seen when the last of its next ``targets_ahead`` comes."""
        return self.fleet.state.targets + targets_ahead - 1

    def solves_within(self, targets_ahead: int) -> bool:
        """Whether one of the fleet's next ``targets_ahead`` targets could wait for a
        solve: the pending one's (:meth:`consolidation_wait`), or, with none pending, the
        one scheduled to fall due among them if it must be applied before their end (or is
        solved inline, without a solver)."""
        if self._pending is not None:
            return self.consolidation_wait(targets_ahead) is not None
        scheduled = self.fleet.scheduled_consolidation()
        if scheduled is None:
            return False
        due, apply_by = scheduled
        return self._seen_by_last(targets_ahead) >= (due if self._solver is None else apply_by)

    def _hand_over_due(self) -> None:
        """Drop a job that was applied or went stale; hand the due consolidation, if
        any, to the solver (:mod:`~routing_svc.service.background_solver`)."""
        if self._solver is None:
            return
        due = self.fleet.due_consolidation()
        if self._pending is not None and self._pending.key != due:
            self._pending.answer.cancel()
            self._pending = None
        if due is not None and self._pending is None:
            job = self.fleet.consolidation_job()
            assert job is not None
            self._pending = PendingConsolidation(job, self._solver.submit(job))

    def apply_vehicle_states(
        self, changes: Sequence[tuple[str, VehicleState[NetPosition]]]
    ) -> tuple[str, str]:
        """Set vehicles' live states, all or none; return the event's payload and result.

        Raises (changing nothing) for an unknown vehicle or a timestamp that goes
        back in time (:meth:`Fleet.set_states`).
        """
        self._check_live()
        self.fleet.set_states(changes)
        encode = self.base_space.encode
        payload = dumps(
            {
                "changes": [
                    {
                        "vehicle": vid,
                        "status": state.status.value,
                        "position": None if state.position is None else encode(state.position),
                        "timestamp": state.timestamp,
                    }
                    for vid, state in changes
                ]
            }
        )
        seq = self.version + 1
        self.version = seq
        changed = sorted({vid for vid, _ in changes})
        vehicles = [self._vehicle_view(self.fleet.vehicle_index(vid)) for vid in changed]
        return payload, dumps({"seq": seq, "version": seq, "vehicles": vehicles})

    def apply_travel_times(self, times: dict[str, float]) -> tuple[str, str]:
        """Replace per-edge travel times (only for ``cost = time``)."""
        self._check_live()
        if self.cost_kind != "time":
            raise Conflict("this fleet uses length costs; travel times apply to cost='time' fleets")
        merged = {**self.travel_times, **times}
        space = self.base_space.with_travel_times(merged)
        self.travel_times = merged
        self.fleet.space = space
        seq = self.version + 1
        self.version = seq
        return dumps({"times": times}), dumps({"seq": seq, "version": seq, "edges": len(times)})

    def apply_delete(self) -> tuple[str, str]:
        self._check_live()
        seq = self.version + 1
        self.version = seq
        self.deleted = True
        return dumps({}), dumps({"seq": seq, "version": seq})

    def replay(self, seq: int, kind: str, payload_json: str, result_json: str | None) -> None:
        """Apply a stored event; check that it reproduces the stored result."""
        if seq != self.version + 1:
            raise ReplayMismatch(f"fleet {self.id}: event {seq} follows version {self.version}")
        payload = json.loads(payload_json)
        if kind == "target":
            target = self.base_space.decode(payload["target"])
            recorded, recorded_for = self._recorded_consolidation(result_json)
            legacy = result_json is not None and '"dispatch"' not in result_json
            _, result = self.apply_target(
                target,
                payload["requires"],
                recorded=recorded,
                recorded_for=recorded_for,
                replaying=True,
                legacy=legacy,
            )
        elif kind == "vehicle_state":
            decode = self.base_space.decode
            changes = [
                (
                    str(c["vehicle"]),
                    VehicleState(
                        Status(c["status"]),
                        None if c["position"] is None else decode(c["position"]),
                        None if c["timestamp"] is None else float(c["timestamp"]),
                    ),
                )
                for c in payload["changes"]
            ]
            _, result = self.apply_vehicle_states(changes)
        elif kind == "weights_updated":
            _, result = self.apply_travel_times(payload["times"])
        elif kind == "fleet_deleted":
            _, result = self.apply_delete()
        else:
            raise ReplayMismatch(f"fleet {self.id}: unknown event kind {kind!r} at {seq}")
        if result_json is not None and result != result_json:
            raise ReplayMismatch(f"fleet {self.id}: event {seq} replays to a different result")

    def _recorded_consolidation(
        self, result_json: str | None
    ) -> tuple[Consolidation[NetPosition] | None, list[str] | None]:
        """The consolidation a stored target result holds (only ``consolidating`` fleets
        record any), and the ids of the vehicles it moved when it names them (a fleet
        that learns per type)."""
        if result_json is None or self.fleet.config.consolidation is None:
            return None, None
        if '"consolidated"' not in result_json:
            return None, None
        data = json.loads(result_json).get("consolidated")
        if data is None:
            return None, None
        vehicles = data.get("vehicles")
        if vehicles is not None and not (
            isinstance(vehicles, list) and all(isinstance(v, str) for v in vehicles)
        ):
            raise ReplayMismatch(
                f"fleet {self.id}: a recorded consolidation's vehicles are malformed"
            )
        return Consolidation.from_dict(data, self.base_space.decode), vehicles

    def _check_live(self) -> None:
        if self.deleted:
            raise Conflict(f"fleet {self.id!r} was deleted")

    # -- views ------------------------------------------------------------------

    def snapshot_json(self) -> str:
        """The whole state as JSON (:func:`~routing_svc.service.canonical.state_dumps`;
        what replay must reproduce bit for bit, :func:`same_snapshot`)."""
        return state_dumps(
            {
                "version": self.version,
                "fleet": self.fleet.snapshot(),
                "travel_times": self.travel_times,
                "cost_sum": self.cost_sum,
                "recent": list(self.recent),
                "deleted": self.deleted,
                "service_levels": self.levels.to_dict(),
            }
        )

    def snapshot_every(self, base: int) -> int:
        """Versions between two stored snapshots: ``base`` for a snapshot of up to
        :data:`SNAPSHOT_POSITIONS` positions, a multiple of it for one that holds more (a
        ``consolidating`` fleet's reservoir), so that writing snapshots costs no more per
        target than a small fleet's, and a restart replays at most that many events."""
        policy = self.fleet.config.consolidation
        held = len(self.fleet.vehicles) + (0 if policy is None else policy.reservoir)
        return base * max(1, -(-held // SNAPSHOT_POSITIONS))

    def restore(self, snapshot_json: str) -> bool:
        """Load :meth:`snapshot_json` output; ``False`` (nothing loaded) for a snapshot
        written before service levels existed: the fleet is then replayed from its
        first event, which derives them."""
        data = json.loads(snapshot_json)
        if "service_levels" not in data:
            return False
        self.levels.restore(data["service_levels"])
        if data["travel_times"]:
            self.travel_times = {k: float(v) for k, v in data["travel_times"].items()}
            self.fleet.space = self.base_space.with_travel_times(self.travel_times)
        self.fleet.restore(data["fleet"])
        self.version = int(data["version"])
        self.cost_sum = float(data["cost_sum"])
        self.recent.clear()
        self.recent.extend(float(c) for c in data["recent"])
        self.deleted = bool(data["deleted"])
        return True

    def describe(self) -> dict[str, Any]:
        """The fleet as the API shows it."""
        cfg = self.fleet.config
        return {
            "id": self.id,
            "network": self.entry.id,
            "cost": self.cost_kind,
            "objective": cfg.objective.name,
            "step": cfg.schedule.to_dict(),
            "counting": cfg.counting.value,
            "annealing": None if cfg.annealing is None else cfg.annealing.to_dict(),
            "seed": cfg.seed,
            "rule": cfg.rule.value,
            "learning_vehicles": cfg.learning_vehicles.value,
            "service_thresholds": list(self.levels.thresholds),
            "probe": cfg.probe,
            "version": self.version,
            "targets": self.fleet.state.targets,
            "vehicles": [self._vehicle_view(i) for i in range(len(self.fleet.vehicles))],
            "reference_demand": None if self.reference is None else self.reference["demand"],
            "stands": self._stands_view(),
            "consolidation": self._consolidation_view(),
        }

    def _consolidation_view(self) -> dict[str, Any] | None:
        """The next consolidation (:meth:`Fleet.scheduled_consolidation`); ``None`` for a
        fleet that does not consolidate."""
        scheduled = self.fleet.scheduled_consolidation()
        if scheduled is None:
            return None
        return {"due_at": scheduled[0], "apply_by": scheduled[1]}

    def _stands_view(self) -> list[dict[str, Any]] | None:
        """Each stand as the API shows it: its ``position``, ``capacity`` and the ids of the
        ``vehicles`` whose reference is at it (:meth:`Fleet.stands`); ``None`` without
        stands."""
        stands = self.fleet.config.stands
        if stands is None:
            return None
        at: dict[NetPosition, list[str]] = {p: [] for p in stands.positions}
        for vehicle_id, position in self.fleet.stands().items():
            at[position].append(vehicle_id)
        return [
            {"position": self.entry.describe(p), "capacity": c, "vehicles": at[p]}
            for p, c in zip(stands.positions, stands.capacities, strict=True)
        ]

    def _vehicle_view(self, index: int) -> dict[str, Any]:
        """A vehicle as the API shows it: its reference (``position``, what learning
        moves), its status and current position (``current``)."""
        fleet = self.fleet
        v = fleet.vehicles[index]
        reference = self.entry.describe(fleet.state.positions[index])
        state = fleet.state.vehicle_states[index]
        return {
            "id": v.id,
            "type": v.type,
            "speed": v.speed,
            "position": reference,
            "reference": reference,
            "status": state.status.value,
            "current": reference if state.position is None else self.entry.describe(state.position),
            "at_reference": state.position is None,
            "timestamp": state.timestamp,
            "updates": fleet.state.updates[index],
        }

    def metrics(self) -> dict[str, Any]:
        """Running means, counts, step sizes and the gap to the optimum."""
        n = self.fleet.state.targets
        fleet = self.fleet
        return {
            "version": self.version,
            "targets": n,
            "mean_cost": self.cost_sum / n if n else None,
            "recent_mean_cost": sum(self.recent) / len(self.recent) if self.recent else None,
            "recent_window": self.recent.maxlen,
            "step_size": {v.id: fleet.step_size(i) for i, v in enumerate(fleet.vehicles)},
            "updates": {v.id: u for v, u in zip(fleet.vehicles, fleet.state.updates, strict=True)},
            "optimum": self._optimum_gap(),
            "service_levels": self.levels.report(),
        }

    def reference_distribution(self) -> DemandDistribution[NetPosition]:
        """The reference demand's atoms (built once from the stored spec)."""
        assert self.reference is not None
        if self._reference_distribution is None:
            self._reference_distribution = build_demand(self.entry, self.reference["demand"])
        return self._reference_distribution

    def _optimum_gap(self) -> dict[str, Any] | None:
        if self.reference is None:
            return None
        optimum = float(self.reference["optimum"]["objective"])
        value = expected_cost_now(self)
        return {
            "kind": self.reference["optimum"].get("kind", "p-median"),
            "objective": optimum,
            "expected_cost": value,
            "gap": gap(value, optimum),
            "method": self.reference["optimum"]["method"],
            "proven_optimal": self.reference["optimum"]["proven_optimal"],
        }


def check_requires(requires: Sequence[str] | None) -> list[str] | None:
    """Normalise a requirement list (``[]`` means any one vehicle)."""
    if requires is None or len(requires) == 0:
        return None
    if any(not isinstance(r, str) or not r for r in requires):
        raise InvalidInput("requires must be a list of non-empty type names")
    return list(requires)


def same_snapshot(replayed: str, stored: str) -> bool:
    """Whether a replayed :meth:`FleetRuntime.snapshot_json` matches a stored one.

    The same values, floats bit for bit, whichever encoder wrote the stored one
    (:func:`~routing_svc.service.canonical.same_state`). A snapshot stored before
    service levels existed lacks their key: the rest must still match.
    """
    if same_state(replayed, stored):
        return True
    data, kept = json.loads(replayed), json.loads(stored)
    if "service_levels" in kept:
        return False
    data.pop("service_levels", None)
    return same_state(state_dumps(data), stored)
