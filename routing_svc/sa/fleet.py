"""A fleet of vehicles deployed by stochastic approximation.

The fleet follows the online-learning shape: :meth:`Fleet.assign` answers who
would serve a target and never changes state; :meth:`Fleet.observe` applies
the update and returns an :class:`Outcome`. Given the same vehicles, config
and stream of targets, the positions are bit-identical (the only randomness,
annealing noise, is derived from the seed and the target's number).

For each target ``z`` (section IV-C of the paper, generalised to any
multiset of required types): for each required type, the closest vehicles of
that type by travel time ``D / v`` are found in one search; the target is
served when the last of them arrives, and only that vehicle moves,
``step_amount`` (eqs. (9)-(10), see :mod:`routing_svc.sa.objectives`) along its
shortest path toward ``z``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Generic

import numpy as np

from routing_svc.errors import Conflict, InvalidInput
from routing_svc.sa.annealing import Annealing
from routing_svc.sa.objectives import Objective
from routing_svc.sa.requirements import build_requirement
from routing_svc.sa.schedules import Counting, Schedule, schedule_from_dict
from routing_svc.sa.space import P, Space


@dataclass(frozen=True, slots=True)
class Vehicle:
    """A vehicle's fixed attributes: id, type and speed factor (1 = reference speed)."""

    id: str
    type: str = "default"
    speed: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not self.id:
            raise InvalidInput("vehicle id must be a non-empty string")
        if not isinstance(self.type, str) or not self.type:
            raise InvalidInput(f"vehicle {self.id!r}: type must be a non-empty string")
        if not math.isfinite(self.speed) or self.speed <= 0.0:
            raise InvalidInput(f"vehicle {self.id!r}: speed must be finite and > 0")


@dataclass(frozen=True, slots=True)
class FleetConfig:
    """How the fleet learns: objective, step schedule, what ``k`` counts, noise, seed."""

    objective: Objective
    schedule: Schedule
    counting: Counting = Counting.VEHICLE
    annealing: Annealing | None = None
    seed: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {
            "objective": self.objective.power,
            "step": self.schedule.to_dict(),
            "counting": self.counting.value,
            "annealing": None if self.annealing is None else self.annealing.to_dict(),
            "seed": self.seed,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FleetConfig:
        annealing = data.get("annealing")
        return cls(
            objective=Objective.parse(data["objective"]),
            schedule=schedule_from_dict(data["step"]),
            counting=Counting(data.get("counting", "vehicle")),
            annealing=None if annealing is None else Annealing.from_dict(annealing),
            seed=int(data.get("seed", 0)),
        )


@dataclass(slots=True)
class FleetState(Generic[P]):
    """The mutable part of a fleet: plain data that serialises to JSON."""

    positions: list[P]
    updates: list[int]
    targets: int = 0


@dataclass(frozen=True, slots=True)
class Dispatch(Generic[P]):
    """Who serves a target (the answer of :meth:`Fleet.assign`)."""

    served_by: tuple[str, ...]
    times: tuple[float, ...]
    moved: str
    cost: float
    """The completion time ``T``: when the last required vehicle arrives."""
    objective: float
    """The service cost ``c(T)``."""


@dataclass(frozen=True, slots=True)
class Outcome(Generic[P]):
    """What one :meth:`Fleet.observe` did."""

    index: int
    """The target's number ``k`` among the fleet's targets (0-based)."""
    dispatch: Dispatch[P]
    step_size: float
    """``gamma_k`` used for the move."""
    moved_by: float
    """Cost travelled along the path (before annealing noise)."""
    noise: float
    """Cost of the random perturbation (0 without annealing)."""
    old_position: P
    new_position: P


@dataclass
class Fleet(Generic[P]):
    """Vehicles, their reference positions and the rule that moves them.

    Vehicles are kept sorted by id, so every tie breaks by vehicle id.
    """

    space: Space[P]
    vehicles: tuple[Vehicle, ...]
    config: FleetConfig
    state: FleetState[P]
    _speeds: np.ndarray = field(init=False, repr=False)
    _types: tuple[str, ...] = field(init=False, repr=False)
    _index: dict[str, int] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.vehicles:
            raise InvalidInput("a fleet needs at least one vehicle")
        ids = [v.id for v in self.vehicles]
        if len(set(ids)) != len(ids):
            raise Conflict("vehicle ids must be unique within a fleet")
        if list(ids) != sorted(ids):
            raise InvalidInput("vehicles must be sorted by id (use Fleet.create)")
        n = len(self.vehicles)
        if len(self.state.positions) != n or len(self.state.updates) != n:
            raise InvalidInput("one position and one update counter per vehicle")
        self._speeds = np.array([v.speed for v in self.vehicles], dtype=np.float64)
        self._types = tuple(v.type for v in self.vehicles)
        self._index = {v.id: i for i, v in enumerate(self.vehicles)}

    @classmethod
    def create(
        cls,
        space: Space[P],
        vehicles: Sequence[tuple[Vehicle, P]],
        config: FleetConfig,
    ) -> Fleet[P]:
        """A new fleet; vehicles (with their starting positions) in any order."""
        ordered = sorted(vehicles, key=lambda pair: pair[0].id)
        return cls(
            space=space,
            vehicles=tuple(v for v, _ in ordered),
            config=config,
            state=FleetState([p for _, p in ordered], [0] * len(ordered), 0),
        )

    @property
    def positions(self) -> dict[str, P]:
        """Every vehicle's reference position, by id."""
        return {v.id: p for v, p in zip(self.vehicles, self.state.positions, strict=True)}

    def step_size(self, vehicle: int) -> float:
        """``gamma_k`` that the next update of ``vehicle`` would use."""
        k = (
            self.state.updates[vehicle]
            if self.config.counting is Counting.VEHICLE
            else self.state.targets
        )
        return self.config.schedule(k)

    def _search(self, target: P, requires: Sequence[str] | None) -> tuple[Dispatch[P], Any]:
        requirement, _ = build_requirement(self._types, requires)
        found = self.space.assign(target, self.state.positions, self._speeds, requirement)
        ids = tuple(self.vehicles[i].id for i in found.served_by)
        dispatch: Dispatch[P] = Dispatch(
            served_by=ids,
            times=found.times,
            moved=self.vehicles[found.mover].id,
            cost=found.completion_time,
            objective=self.config.objective.cost(found.completion_time),
        )
        return dispatch, found

    def assign(self, target: P, requires: Sequence[str] | None = None) -> Dispatch[P]:
        """Who would serve ``target``; changes nothing."""
        return self._search(target, requires)[0]

    def observe(self, target: P, requires: Sequence[str] | None = None) -> Outcome[P]:
        """Serve ``target`` and move the last-arriving vehicle toward it (eqs. (9)-(10))."""
        dispatch, found = self._search(target, requires)
        mover = found.mover
        gamma = self.step_size(mover)
        amount = self.config.objective.step_amount(
            gamma=gamma, path_cost=found.mover_cost, speed=float(self._speeds[mover])
        )
        old = self.state.positions[mover]
        new = self.space.advance(old, target, found.route, amount) if amount > 0.0 else old
        noise = 0.0
        if self.config.annealing is not None:
            noise, rng = self.config.annealing.amount(seed=self.config.seed, k=self.state.targets)
            if noise > 0.0:
                new = self.space.perturb(new, noise, rng)
        index = self.state.targets
        self.state.positions[mover] = new
        self.state.updates[mover] += 1
        self.state.targets += 1
        return Outcome(index, dispatch, gamma, amount, noise, old, new)

    def snapshot(self) -> dict[str, Any]:
        """JSON-ready state (floats round-trip exactly through ``json``)."""
        return {
            "positions": [self.space.encode(p) for p in self.state.positions],
            "updates": list(self.state.updates),
            "targets": self.state.targets,
        }

    def restore(self, data: dict[str, Any]) -> None:
        """Load a :meth:`snapshot` taken from a fleet with the same vehicles."""
        positions = [self.space.decode(p) for p in data["positions"]]
        updates = [int(u) for u in data["updates"]]
        if len(positions) != len(self.vehicles) or len(updates) != len(self.vehicles):
            raise InvalidInput("snapshot does not match the fleet's vehicles")
        self.state = FleetState(positions, updates, int(data["targets"]))

    def vehicle_index(self, vehicle_id: str) -> int:
        """Index of a vehicle by id (vehicles are sorted by id)."""
        try:
            return self._index[vehicle_id]
        except KeyError:
            raise InvalidInput(f"unknown vehicle {vehicle_id!r}") from None
