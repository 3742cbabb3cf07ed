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

Vehicles also have a live state (:mod:`routing_svc.sa.live`): available or
not, and where they are now. The same search answers who goes now
(:attr:`Dispatch.sent`: the closest *available* vehicles by *current*
position) apart from whose *reference* moves; :class:`LearningVehicles`
chooses whether the mover is the closest reference of all vehicles (the
paper's) or of the available ones. Under ``consolidating`` the held step acts
on that mover's reference and consolidations on all references, as before
(references are where vehicles wait when idle, busy or not); a fleet of several
types consolidates each type's references on the targets that needed that type
(:attr:`Fleet.learns_per_type`).

Three rules (:class:`Rule`): the paper's step alone; the paper's step with the
backward probe; and ``consolidating``, the paper's step held at junctions
(:mod:`routing_svc.sa.held_step`) with periodic consolidations
(:mod:`routing_svc.sa.consolidation`), the default of new fleets.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from itertools import compress, count
from operator import is_not, ne
from typing import Any, Generic, NamedTuple, cast

import numpy as np

from routing_svc.errors import Conflict, InvalidInput, NotFound, ReplayMismatch
from routing_svc.sa.annealing import Annealing
from routing_svc.sa.consolidation import (
    NO_SHIFT_RUN,
    Consolidation,
    ConsolidationJob,
    ConsolidationKey,
    ConsolidationPolicy,
    SampleSpace,
    ShiftRun,
    move_pays,
    partners_of,
)
from routing_svc.sa.held_step import Hold, JunctionSpace, held_step
from routing_svc.sa.live import (
    LearningVehicles,
    Sent,
    Status,
    VehicleState,
    live_search,
    sent_from,
)
from routing_svc.sa.objectives import Objective
from routing_svc.sa.posts import Post, fleet_posts
from routing_svc.sa.requirements import build_requirement
from routing_svc.sa.schedules import Counting, Schedule, schedule_from_dict
from routing_svc.sa.space import (
    Assignment,
    DirectedSpace,
    P,
    Requirement,
    SingleTargetServing,
    Space,
)
from routing_svc.sa.stands import StandSet, vehicle_stands
from routing_svc.sa.step_rule import probe_gains, probe_step

"""Relative gain below which a probe is taken as no better (rounding of equal paths)."""


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


class Rule(StrEnum):
    """The learning rule of a fleet."""

    PAPER = "paper"
    """Eq. (10) alone: the mover steps ``gamma_k`` toward the target."""
    PROBE = "probe"
    """Eq. (10) with the backward probe (:attr:`FleetConfig.probe`)."""
    CONSOLIDATING = "consolidating"
    """Eq. (10) held at junctions, and consolidations of recent targets."""


@dataclass(frozen=True, slots=True)
class FleetConfig:
    """How the fleet learns: objective, step schedule, what ``k`` counts, noise, seed, rule."""

    objective: Objective
    schedule: Schedule
    counting: Counting = Counting.VEHICLE
    annealing: Annealing | None = None
    seed: int = 0
    probe: float | None = None
    """Window ``h`` (cost) of the backward finite difference on a :class:`DirectedSpace`.

    The paper's step (eq. (10)) is a stochastic gradient of the smooth part of
    ``J`` only; on a directed network ``J`` also jumps where a reference passes
    a target or a junction, and the step never sees it (its fixed points are
    then not p-median optima). With a window, each target is also served from
    one probe per vehicle ``j``, a point ``h`` behind its reference (or the
    junction it last gave turns up at); every ``j`` whose probe serves the target
    ``G_j > 0`` faster than the fleet does moves back toward it by
    ``min(h, gamma_j G_j / h)``, a Kiefer-Wolfowitz estimate of the jump term of
    the gradient. ``None``: exactly the paper's rule. Targets with requirements
    (several types) make no probe.
    """
    prior_counts: tuple[int, ...] = ()
    """Per vehicle (in the fleet's id order), the targets of a prior sample it
    serves from its starting position (:func:`prior_counts`): its step counter
    starts there, so a fleet started at the p-median of that sample goes on
    with the small steps of a fleet that has seen it. Empty: all zero."""
    window: float | None = None
    """``consolidating`` only: the pressure ``h`` (cost) that takes a reference off a
    junction (:func:`routing_svc.sa.held_step.held_step`)."""
    consolidation: ConsolidationPolicy | None = None
    """``consolidating`` only: when to consolidate."""
    learning_vehicles: LearningVehicles = LearningVehicles.ALL
    """Among which vehicles the closest reference moves (:class:`LearningVehicles`):
    all (the paper's eq. (10)) or the available ones only."""
    stands: StandSet[Any] | None = None
    """The stands the vehicles may park at (:mod:`routing_svc.sa.stands`): a
    consolidation solves over them only, with their capacities; ``None``: anywhere."""
    per_type: bool = False
    """``consolidating`` only: a fleet of several types consolidates each type
    (:attr:`Fleet.learns_per_type`); ``False``, as fleets stored before it did, only
    the held step."""

    def __post_init__(self) -> None:
        if self.per_type and self.consolidation is None:
            raise InvalidInput("learning per type belongs to the 'consolidating' rule")
        if self.consolidation is None and self.window is None:
            return
        if self.consolidation is None or self.window is None:
            raise InvalidInput("a consolidating fleet needs both a window and a policy")
        if not (math.isfinite(self.window) and self.window > 0.0):
            raise InvalidInput("the junction window must be a finite cost > 0")
        if self.probe is not None or self.annealing is not None:
            raise InvalidInput("a consolidating fleet takes neither a probe nor annealing")

    @property
    def rule(self) -> Rule:
        """The learning rule these settings give."""
        if self.consolidation is not None:
            return Rule.CONSOLIDATING
        return Rule.PAPER if self.probe is None else Rule.PROBE

    def to_dict(self, encode: Callable[[Any], dict[str, object]] | None = None) -> dict[str, Any]:
        """The settings as JSON; ``encode`` writes the stands' positions (needed with
        stands)."""
        data: dict[str, Any] = {
            "objective": self.objective.power,
            "step": self.schedule.to_dict(),
            "counting": self.counting.value,
            "annealing": None if self.annealing is None else self.annealing.to_dict(),
            "seed": self.seed,
            "probe": self.probe,
            **({"prior_counts": list(self.prior_counts)} if self.prior_counts else {}),
        }
        if self.consolidation is not None:
            data["rule"] = Rule.CONSOLIDATING.value
            data["window"] = self.window
            data["consolidation"] = self.consolidation.to_dict()
            if self.per_type:
                data["per_type"] = True
        if self.learning_vehicles is not LearningVehicles.ALL:
            data["learning_vehicles"] = self.learning_vehicles.value
        if self.stands is not None:
            if encode is None:
                raise InvalidInput("writing a fleet's stands needs its space's encoder")
            data["stands"] = self.stands.to_dict(encode)
        return data

    @classmethod
    def from_dict(
        cls, data: dict[str, Any], decode: Callable[[dict[str, object]], Any] | None = None
    ) -> FleetConfig:
        """Settings from :meth:`to_dict`; a dict without ``rule`` (stored before the
        rule existed) keeps the probe rule or the paper's, as it was; without
        ``learning_vehicles``, all vehicles learn; without ``stands``, vehicles park
        anywhere (``decode`` reads the stands' positions)."""
        stands = data.get("stands")
        if stands is not None and decode is None:
            raise InvalidInput("reading a fleet's stands needs its space's decoder")
        annealing = data.get("annealing")
        rule = Rule(data.get("rule", Rule.PROBE if data.get("probe") is not None else "paper"))
        consolidating = rule is Rule.CONSOLIDATING
        return cls(
            objective=Objective.parse(data["objective"]),
            schedule=schedule_from_dict(data["step"]),
            counting=Counting(data.get("counting", "vehicle")),
            annealing=None if annealing is None else Annealing.from_dict(annealing),
            seed=int(data.get("seed", 0)),
            probe=None if data.get("probe") is None else float(data["probe"]),
            prior_counts=tuple(int(c) for c in data.get("prior_counts", ())),
            window=float(data["window"]) if consolidating else None,
            consolidation=ConsolidationPolicy.from_dict(data["consolidation"])
            if consolidating
            else None,
            learning_vehicles=LearningVehicles(data.get("learning_vehicles", "all")),
            stands=None if stands is None or decode is None else StandSet.from_dict(stands, decode),
            per_type=consolidating and bool(data.get("per_type", False)),
        )


@dataclass(slots=True)
class FleetState(Generic[P]):
    """The mutable part of a fleet: plain data that serialises to JSON."""

    positions: list[P]
    updates: list[int]
    targets: int = 0
    entries: list[P | None] = field(default_factory=list)
    """Per vehicle, the junction behind its reference whose turns it gave up (the end
    of an edge, see :meth:`DirectedSpace.entry`), or ``None`` when unknown; kept only
    with :attr:`FleetConfig.probe`. Empty means all unknown."""
    learning: Learning[P] | None = None
    """The ``consolidating`` rule's own state for the whole fleet (``None`` for the other
    rules, and for a fleet that learns per type)."""
    vehicle_states: list[VehicleState[P]] = field(default_factory=list)
    """Per vehicle, its live state (:class:`~routing_svc.sa.live.VehicleState`); empty
    means every vehicle is available at its reference. Replaced, never changed in place."""
    type_learning: dict[str, Learning[P]] = field(default_factory=dict)
    """The ``consolidating`` rule's state per vehicle type, for a fleet that learns per
    type (:attr:`Fleet.learns_per_type`); empty otherwise."""


@dataclass(slots=True)
class Learning(Generic[P]):
    """What the ``consolidating`` rule keeps besides the references."""

    holds: list[Hold[P] | None]
    """Per vehicle, its hold on a junction (:class:`~routing_svc.sa.held_step.Hold`)."""
    anchor: list[P]
    """The last accepted references (at first, the starting ones)."""
    reservoir: deque[P]
    """The most recent targets that needed any one vehicle, oldest first."""
    epoch: int = 0
    """Target count at which the current epoch of the demand began."""
    next_consolidation: int = 0
    """Target count at which the next consolidation is due."""
    baseline: float | None = None
    """:attr:`Consolidation.baseline` of the last consolidation (``None``: none yet)."""
    accepted_at: int = 0
    """Target count at which the current references were accepted (or started)."""
    fitted: int = 0
    """Reservoir targets the current references were fitted to by a consolidation of
    this epoch (0: they were not)."""
    hastened_at: int = 0
    """Target count of the last consolidation that restarted the epoch's clock
    (:meth:`ConsolidationPolicy.hastens`; 0: none)."""
    block_cost: float = 0.0
    block_size: int = 0
    block_squares: float = 0.0
    """Sum of the squared costs of the current block (the shift test's spread)."""
    run: ShiftRun = NO_SHIFT_RUN
    """The blocks in a row that exceeded the shift ratio: their costs' sum, their
    squares' sum and their size (:meth:`ConsolidationPolicy.starts_epoch`)."""
    vehicles: tuple[int, ...] = ()
    """The vehicles (fleet indices) this state learns for, in the order of ``holds``
    and ``anchor``: the whole fleet's, or one type's (:attr:`FleetState.type_learning`)."""
    seen: int = 0
    """One type's: the targets that needed its type, the counts it schedules by (the
    whole fleet's state schedules by the fleet's targets)."""
    partners: deque[tuple[str, ...]] = field(default_factory=deque)
    """One type's: per reservoir target, in its order, the other types it needed (empty
    for a target of this type alone); empty for the whole fleet's."""
    served: tuple[int, ...] | None = None
    """The reservoir targets each vehicle served at the last accepted consolidation of
    the epoch, the shares the test of the winners expects
    (:meth:`ConsolidationPolicy.shares_moved`; ``None``: none yet)."""
    wins: list[int] = field(default_factory=list)
    """Per vehicle, the targets of the current block of that test whose closest
    reference was its (empty: no block begun)."""
    won: int = 0
    """The targets of that block (the sum of ``wins``)."""


class Dispatch(NamedTuple, Generic[P]):
    """Who serves a target (the answer of :meth:`Fleet.assign`)."""

    served_by: tuple[str, ...]
    times: tuple[float, ...]
    moved: str
    cost: float
    """The completion time ``T``: when the last required vehicle arrives."""
    objective: float
    """The service cost ``c(T)``."""
    sent: Sent | None = None
    """Who goes now: the closest available vehicles by current position (the
    learning answer above names whose *reference* is closest). :class:`Fleet` always
    fills it."""


class Outcome(NamedTuple, Generic[P]):
    """What one :meth:`Fleet.observe` did."""

    target_number: int
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
    backed_off: tuple[tuple[int, P], ...] = ()
    """Vehicles (index, new position) that the backward probe moved back, in index
    order; the mover among them made no forward step (:attr:`FleetConfig.probe`)."""
    consolidation: Consolidation[P] | None = None
    """The consolidation this target triggered, applied after its step (``consolidating``)."""
    consolidated: tuple[str, ...] = ()
    """The ids of the vehicles whose references :attr:`consolidation` gives, in its
    order: the whole fleet's, or one type's (:attr:`Fleet.learns_per_type`)."""


@dataclass
class _ProbeCache(Generic[P]):
    """The back probes of :meth:`Fleet._probe` and the references they were taken at."""

    space: object
    window: float
    positions: list[P]
    entries: list[P | None]
    probes: list[P]


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
    _ids: tuple[str, ...] = field(init=False, repr=False)
    _any_one: Requirement = field(init=False, repr=False)
    _identical: bool = field(init=False, repr=False)
    _type_groups: dict[str, tuple[int, ...]] | None = field(init=False, repr=False)
    _slot: tuple[int, ...] = field(init=False, repr=False)
    _probe_cache: _ProbeCache[P] | None = field(init=False, repr=False, default=None)
    _compiled: tuple[object, FleetConfig, SingleTargetServing[P] | None] | None = field(
        init=False, repr=False, default=None
    )
    _gammas: tuple[FleetState[P], FleetConfig, list[int], np.ndarray] | None = field(
        init=False, repr=False, default=None
    )
    _resting: tuple[list[VehicleState[P]], bool] | None = field(
        init=False, repr=False, default=None
    )
    defer_consolidations: bool = field(default=False, kw_only=True)
    """A due consolidation waits to be solved away from the fleet
    (:meth:`consolidation_job`) and handed to :meth:`observe` as ``solved``, instead of
    being solved inside the target that made it due."""

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
        prior = self.config.prior_counts
        if prior and (len(prior) != n or min(prior) < 0):
            raise InvalidInput("prior_counts needs one count >= 0 per vehicle")
        if not self.state.entries:
            self.state.entries = [None] * n
        if len(self.state.entries) != n:
            raise InvalidInput("one entry (or None) per vehicle")
        if not self.state.vehicle_states:
            self.state.vehicle_states = [VehicleState() for _ in range(n)]
        if len(self.state.vehicle_states) != n:
            raise InvalidInput("one vehicle state per vehicle")
        if self.config.stands is not None:
            self.config.stands.check_fleet(n)
        self._speeds = np.array([v.speed for v in self.vehicles], dtype=np.float64)
        self._types = tuple(v.type for v in self.vehicles)
        self._index = {v.id: i for i, v in enumerate(self.vehicles)}
        self._ids = tuple(v.id for v in self.vehicles)
        self._any_one, _ = build_requirement(self._types, None)
        self._identical = len(set(self._types)) == 1 and bool(
            np.all(self._speeds == self._speeds[0])
        )
        self._type_groups = self._groups_by_type()
        slot = list(range(n))
        for members in (self._type_groups or {}).values():
            for local, i in enumerate(members):
                slot[i] = local
        self._slot = tuple(slot)
        policy = self.config.consolidation
        if policy is None:
            return
        if self._type_groups is None:
            if self.state.learning is None:
                self.state.learning = self._new_learning(
                    policy, tuple(range(n)), self.state.targets
                )
        elif not self.state.type_learning:
            self.state.type_learning = {
                kind: self._new_learning(policy, members, 0)
                for kind, members in self._type_groups.items()
            }

    def _new_learning(
        self, policy: ConsolidationPolicy, members: tuple[int, ...], now: int
    ) -> Learning[P]:
        """A fresh learning state for the vehicles ``members`` at count ``now``."""
        return Learning(
            holds=[None] * len(members),
            anchor=[self.state.positions[i] for i in members],
            reservoir=deque(maxlen=policy.reservoir),
            partners=deque(maxlen=policy.reservoir),
            epoch=now,
            next_consolidation=now + policy.first,
            accepted_at=now,
            vehicles=members,
        )

    def _groups_by_type(self) -> dict[str, tuple[int, ...]] | None:
        """Each type's vehicles when the fleet learns per type (:attr:`learns_per_type`),
        else ``None``."""
        config = self.config
        if config.consolidation is None or not config.per_type or self._identical:
            return None
        if config.stands is not None:
            return None
        return type_groups(self._types, self._speeds.tolist())

    @property
    def learns_per_type(self) -> bool:
        """Whether the ``consolidating`` rule runs once per vehicle type.

        Objective (11) of targets that each need one vehicle of one type is a sum of
        one p-median per type, so each type's vehicles consolidate on the recent
        targets that needed their type, on their own clock (:attr:`Learning.seen`); a
        target of several types feeds each, and a type's consolidation prices it by its
        last arrival with the other types' references fixed (``floors`` of
        :func:`~routing_svc.sa.consolidation.consolidate`). A fleet learns so under
        ``consolidating`` (with :attr:`FleetConfig.per_type`) when it has several types,
        each type's vehicles share one speed, and it has no stands (their capacities are
        shared between types); targets for any one vehicle make held steps only.
        """
        return self._type_groups is not None

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
            state=FleetState([p for _, p in ordered], [0] * len(ordered), 0, [None] * len(ordered)),
        )

    @property
    def positions(self) -> dict[str, P]:
        """Every vehicle's reference position, by id."""
        return {v.id: p for v, p in zip(self.vehicles, self.state.positions, strict=True)}

    def stands(self) -> dict[str, P]:
        """Every vehicle's stand (:func:`routing_svc.sa.stands.stand_assignment`), by id;
        a fleet without stands waits at its references."""
        stands = self.config.stands
        if stands is None:
            return self.positions
        space = cast(SampleSpace[P], self.space)
        at = vehicle_stands(space.cost_matrix, stands, self.state.positions)
        return {v.id: p for v, p in zip(self.vehicles, at, strict=True)}

    def step_size(self, vehicle: int) -> float:
        """``gamma_k`` that the next update of ``vehicle`` would use."""
        prior = self.config.prior_counts
        if self.config.counting is Counting.VEHICLE:
            k = self.state.updates[vehicle] + (prior[vehicle] if prior else 0)
        else:
            k = self.state.targets + sum(prior)
        return self.config.schedule(k)

    def _search(self, target: P, requires: Sequence[str] | None) -> tuple[Dispatch[P], Any]:
        """One search for both answers: who goes now and whose reference moves."""
        if not requires and self.at_rest():
            found = self._compiled_search(target)
            if found is not None:  # any one vehicle: the mover goes
                moved = self._ids[found.mover]
                time = found.completion_time
                sent = Sent((moved,), ("*",), (time,))
                cost = self.config.objective.cost(time)
                return Dispatch((moved,), (time,), moved, time, cost, sent), found
        if requires:
            requirement, names = build_requirement(self._types, requires)
        else:
            requirement, names = self._any_one, ("*",)
        ids = self._ids
        if self.at_rest():
            found = self.space.assign(target, self.state.positions, self._speeds, requirement)
            sent = sent_from(found, ids, names, requirement.counts)
        else:
            answer = live_search(
                self.space,
                target,
                references=self.state.positions,
                speeds=self._speeds,
                vehicle_ids=ids,
                requirement=requirement,
                names=names,
                states=self.state.vehicle_states,
                learning_vehicles=self.config.learning_vehicles,
            )
            found, sent = answer.learning, answer.sent
        dispatch: Dispatch[P] = Dispatch(
            served_by=tuple(ids[i] for i in found.served_by),
            times=found.times,
            moved=ids[found.mover],
            cost=found.completion_time,
            objective=self.config.objective.cost(found.completion_time),
            sent=sent,
        )
        return dispatch, found

    def at_rest(self) -> bool:
        """Whether every vehicle is available at its reference (then the dispatch answer
        is the learning answer, under either :class:`LearningVehicles` rule)."""
        states = self.state.vehicle_states
        kept = self._resting
        if kept is not None and kept[0] is states:
            return kept[1]
        resting = all(s.status is Status.AVAILABLE and s.position is None for s in states)
        self._resting = (states, resting)
        return resting

    def vehicle_state(self, vehicle_id: str) -> VehicleState[P]:
        """A vehicle's live state."""
        return self.state.vehicle_states[self.vehicle_index(vehicle_id)]

    def set_states(self, changes: Sequence[tuple[str, VehicleState[P]]]) -> None:
        """Set vehicles' live states, all or none.

        Each change is a vehicle id and its new state, applied in order. A change
        without a timestamp keeps the vehicle's last one. Raises before changing
        anything.

        Raises
        ------
        NotFound
            An unknown vehicle.
        Conflict
            A timestamp before the vehicle's last one (a report that goes back in time).
        """
        states = list(self.state.vehicle_states)
        for vehicle_id, new in changes:
            index = self.vehicle_index(vehicle_id)
            last = states[index].timestamp
            if new.timestamp is not None and last is not None and new.timestamp < last:
                raise Conflict(
                    f"vehicle {vehicle_id!r}: state at {new.timestamp} goes back before its "
                    f"last report at {last}"
                )
            if new.timestamp is None and last is not None:
                new = VehicleState(new.status, new.position, last)
            states[index] = new
        self.state.vehicle_states = states

    def posts(self) -> list[Post[P]]:
        """Where each available vehicle should wait now (:func:`routing_svc.sa.posts.fleet_posts`),
        on the reservoir of recent targets as the demand sample (of a fleet that learns per
        type, each type's: the targets that needed it; the references themselves without
        one); changes nothing.

        Raises
        ------
        InvalidInput
            If the space has no cost matrix.
        """
        if not _offers(type(self.space), "cost_matrix"):
            raise InvalidInput("posts need a space with a cost matrix")
        space = cast(SampleSpace[P], self.space)
        return fleet_posts(
            space.cost_matrix,
            references=self.state.positions,
            speeds=self._speeds,
            types=self._types,
            states=self.state.vehicle_states,
            sample={kind: list(kept.reservoir) for kind, kept in self.state.type_learning.items()}
            if self._type_groups is not None
            else [z for learning in self._learnings() for z in learning.reservoir],
            power=self.config.objective.power,
        )

    def assign(self, target: P, requires: Sequence[str] | None = None) -> Dispatch[P]:
        """Who would go now (:attr:`Dispatch.sent`) and whose reference would move;
        changes nothing."""
        return self._search(target, requires)[0]

    def observe(
        self,
        target: P,
        requires: Sequence[str] | None = None,
        *,
        solved: Solved[P] | None = None,
    ) -> Outcome[P]:
        """Serve ``target`` and move the last-arriving vehicle toward it (eqs. (9)-(10)).

        A target for any one vehicle, without annealing noise, goes through the
        space's compiled form of this update when it has one
        (:class:`~routing_svc.sa.space.SingleTargetServing`), with the same result.
        ``solved``: a consolidation solved away from the fleet (:meth:`consolidation_job`),
        applied (and returned in the outcome) if it is still the due one, else dropped.
        """
        if self.config.consolidation is not None:
            return self._observe_held(self.config.consolidation, target, requires, solved=solved)
        if not requires and self.config.annealing is None and self.at_rest():
            serving = self._serving()
            if serving is not None:
                outcome = self._observe_compiled(serving, target)
                if outcome is not None:
                    return outcome
        dispatch, found = self._search(target, requires)
        mover = found.mover
        gamma = self.step_size(mover)
        amount = self.config.objective.step_amount(
            gamma=gamma, path_cost=found.mover_cost, speed=float(self._speeds[mover])
        )
        old = self.state.positions[mover]
        probing = self._probing()
        backed_off: list[tuple[int, P]] = []
        if probing is not None and not requires:
            backed_off = self._probe(*probing, target, found.completion_time)
            if any(j == mover for j, _ in backed_off):
                amount = 0.0
        start = self.state.positions[mover]  # ``old`` unless the probe moved the mover back
        new = self.space.advance(start, target, found.route, amount) if amount > 0.0 else start
        entry = self.state.entries[mover]
        if probing is not None and amount > 0.0:
            directed, window = probing
            entry = directed.entry(start, new, found.route, entry, window)
        noise = 0.0
        if self.config.annealing is not None:
            noise, rng = self.config.annealing.amount(seed=self.config.seed, k=self.state.targets)
            if noise > 0.0:
                walked = self.space.perturb(new, noise, rng)
                if probing is not None:
                    entry = probing[0].entry(new, walked, None, entry, probing[1])
                new = walked
        index = self.state.targets
        self.state.positions[mover] = new
        self.state.entries[mover] = entry
        self.state.updates[mover] += 1
        self.state.targets += 1
        return Outcome(index, dispatch, gamma, amount, noise, old, new, tuple(backed_off))

    def _observe_held(
        self,
        policy: ConsolidationPolicy,
        target: P,
        requires: Sequence[str] | None,
        *,
        recorded: Consolidation[P] | None = None,
        recorded_for: tuple[str, ...] | None = None,
        replaying: bool = False,
        solved: Solved[P] | None = None,
    ) -> Outcome[P]:
        """:meth:`observe` under the ``consolidating`` rule: the held step of the mover
        (:func:`~routing_svc.sa.held_step.held_step`; a move it would make is dropped,
        with its pressure, while no consolidation of the epoch has fitted the references
        (:attr:`ConsolidationPolicy.unfitted_confidence`) or unless
        :func:`~routing_svc.sa.consolidation.move_pays` on the reservoir), then the shift
        test and, when due, a consolidation (see :meth:`_learn_from` for ``recorded``,
        ``replaying`` and ``solved``; ``recorded_for``: the ids of the vehicles it moved,
        when known). The mover's hold and checks are its group's (:attr:`learns_per_type`);
        the target feeds the groups it needs (:meth:`_fed_by`), and makes at most one
        consolidation, the first due in type order (another stays due)."""
        dispatch, found = self._search(target, requires)
        state = self.state
        mover = found.mover
        gamma = self.step_size(mover)
        amount = self.config.objective.step_amount(
            gamma=gamma, path_cost=found.mover_cost, speed=float(self._speeds[mover])
        )
        old = state.positions[mover]
        space = self.space
        if _has_junctions(type(space)):
            assert self.config.window is not None
            keeper, local = self._learning_of(mover)
            new, moved, hold = held_step(
                cast(JunctionSpace[P], space),
                old,
                target,
                found.route,
                amount=amount,
                path_cost=found.mover_cost,
                hold=keeper.holds[local],
                window=self.config.window,
            )
            if (
                moved > 0.0
                and self._consolidates()
                and (
                    (policy.unfitted_confidence and keeper.fitted == 0)
                    or (
                        policy.checked_moves
                        and not move_pays(
                            cast(SampleSpace[P], space),
                            self._group_positions(keeper),
                            local,
                            new,
                            list(keeper.reservoir),
                            power=self.config.objective.power,
                            speed=float(self._speeds[mover]),
                        )
                    )
                )
            ):
                new, moved, hold = old, 0.0, None
            keeper.holds[local] = hold
        else:
            new = space.advance(old, target, found.route, amount) if amount > 0.0 else old
            moved = amount
        index = state.targets
        state.positions[mover] = new
        state.updates[mover] += 1
        state.targets += 1
        consolidation: Consolidation[P] | None = None
        consolidated: tuple[str, ...] = ()
        fed = self._fed_by(requires, dispatch.objective) if self._consolidates() else []
        if recorded is not None and recorded_for is None and len(fed) > 1:
            raise ReplayMismatch("a consolidation recorded for several types names no vehicles")
        for learning, cost, partners in fed:  # one consolidation at most: the first due
            if self._type_groups is not None:
                learning.seen += 1
            free = consolidation is None
            mine = (
                recorded
                if free
                and recorded is not None
                and (recorded_for is None or recorded_for == self._group_ids(learning))
                else None
            )
            done = self._learn_from(
                learning,
                policy,
                target,
                cost,
                mine,
                replaying,
                solved,
                partners=partners,
                may_consolidate=free,
                winner=self._slot[mover] if self._tests_winners() else None,
            )
            if done is not None:
                consolidation, consolidated = done, self._group_ids(learning)
        if recorded is not None and consolidation is None:
            raise ReplayMismatch("a consolidation was recorded for a target that makes none")
        return Outcome(
            index, dispatch, gamma, moved, 0.0, old, new, (), consolidation, consolidated
        )

    def _consolidates(self) -> bool:
        """Whether this fleet can consolidate: a space that can, and one type and one
        speed, or one speed per type (:attr:`learns_per_type`)."""
        return (self._identical or self._type_groups is not None) and _samples(type(self.space))

    def _tests_winners(self) -> bool:
        """Whether the shift test also tests who won each block
        (:meth:`ConsolidationPolicy.shares_moved`): in a fleet that learns as one, where
        the vehicle that moves is the one whose reference is closest."""
        policy = self.config.consolidation
        return (
            policy is not None
            and policy.share_alpha is not None
            and self._type_groups is None
            and self.config.learning_vehicles is LearningVehicles.ALL
        )

    def _learnings(self) -> list[Learning[P]]:
        """The ``consolidating`` rule's states: the whole fleet's, or one per type."""
        if self.state.learning is not None:
            return [self.state.learning]
        return list(self.state.type_learning.values())

    def _fed_by(
        self, requires: Sequence[str] | None, cost: float
    ) -> list[tuple[Learning[P], float, tuple[str, ...]]]:
        """The learning states a target feeds, each with the cost its shift test sees
        (the target's ``cost``, its last arrival) and the other types it needs.

        The whole fleet's, for a target that needs any one vehicle. For a fleet that
        learns per type (:attr:`learns_per_type`), each type the target needs, in name
        order; a consolidation of a type prices a target that needed other types too by
        its last arrival, theirs from their current references
        (:meth:`ConsolidationJob.floors`). A target that needs any one vehicle feeds
        every type, each pricing it by the first arrival of the others
        (:meth:`ConsolidationJob.ceilings`), under
        :attr:`ConsolidationPolicy.shared_targets`; else none.
        """
        if self._type_groups is None:
            learning = self.state.learning
            return [] if requires or learning is None else [(learning, cost, ())]
        if not requires:
            policy = self.config.consolidation
            if policy is None or not policy.shared_targets:
                return []
            return [
                (learning, cost, partners_of(kind, None))
                for kind, learning in self.state.type_learning.items()
            ]
        return [
            (self.state.type_learning[k], cost, partners_of(k, requires))
            for k in sorted(set(requires))
        ]

    def _learning_of(self, vehicle: int) -> tuple[Learning[P], int]:
        """The learning state that holds ``vehicle``, and its index there."""
        kept = self.state.learning
        if kept is None:
            kept = self.state.type_learning[self._types[vehicle]]
        return kept, self._slot[vehicle]

    def _group_positions(self, learning: Learning[P]) -> list[P]:
        """The references of the vehicles ``learning`` learns for, in its order."""
        return [self.state.positions[i] for i in learning.vehicles]

    def _group_ids(self, learning: Learning[P]) -> tuple[str, ...]:
        """The ids of the vehicles ``learning`` learns for, in its order."""
        return tuple(self._ids[i] for i in learning.vehicles)

    def _clock(self, learning: Learning[P]) -> int:
        """The target count ``learning`` schedules by: the fleet's, or its type's."""
        return self.state.targets if self._type_groups is None else learning.seen

    def _learn_from(
        self,
        learning: Learning[P],
        policy: ConsolidationPolicy,
        target: P,
        cost: float,
        recorded: Consolidation[P] | None,
        replaying: bool,
        solved: Solved[P] | None,
        *,
        partners: tuple[str, ...] = (),
        may_consolidate: bool = True,
        winner: int | None = None,
    ) -> Consolidation[P] | None:
        """Keep ``target``, run the shift tests on its ``cost`` and on the vehicle whose
        reference was closest (``winner``, its index in ``learning``; ``None``: no test
        of the winners) and consolidate when due (and ``may_consolidate``: else it stays
        due).

        A due consolidation is, in replay (``replaying``), the ``recorded`` one or none
        (it was solved away from the fleet and applied at a later target); live,
        ``solved`` when it answers this due one (its key), else none while
        :attr:`defer_consolidations`, else solved here."""
        state = self.state
        now = self._clock(learning)
        learning.reservoir.append(target)
        if self._type_groups is not None:
            learning.partners.append(partners)
        learning.block_cost += cost
        learning.block_squares += cost * cost
        learning.block_size += 1
        if learning.block_size >= policy.block:
            block = (learning.block_cost, learning.block_squares, learning.block_size)
            learning.run = policy.shift_run(learning.run, block, learning.baseline)
            total, squares, size = learning.run
            if policy.starts_epoch(
                cost_sum=total, square_sum=squares, size=size, baseline=learning.baseline
            ):
                _new_epoch(learning, policy, now)
            learning.block_cost, learning.block_squares, learning.block_size = 0.0, 0.0, 0
        if winner is not None and learning.served is not None:
            if not learning.wins:
                learning.wins = [0] * len(learning.served)
            learning.wins[winner] += 1
            learning.won += 1
            if learning.won >= policy.block:
                places = self._group_positions(learning)
                if policy.shares_moved(learning.wins, learning.served, places):
                    _new_epoch(learning, policy, now)
                learning.wins, learning.won = [], 0
        if now < learning.next_consolidation:
            if recorded is not None:
                raise ReplayMismatch("a consolidation was recorded where none was due")
            return None
        if not may_consolidate:
            return None
        if replaying:
            if recorded is None:  # solved away from the fleet, applied at a later target
                return None
            done = recorded
        elif solved is not None and solved[0] == self._key(learning):
            done = solved[1]
        elif self.defer_consolidations:
            return None
        else:
            job = self._job(learning)
            done = job.solve()
        members = learning.vehicles
        if len(done.positions) != len(members) or len(done.updates) != len(members):
            raise ReplayMismatch("a recorded consolidation does not match the fleet's vehicles")
        if done.accepted:
            for i, position, updates in zip(members, done.positions, done.updates, strict=True):
                state.positions[i] = position
                state.updates[i] = updates
            learning.anchor = list(done.positions)
            learning.holds = [None] * len(members)
            learning.accepted_at = now
            learning.fitted = done.sample
            learning.served, learning.wins, learning.won = done.updates, [], 0
            if policy.hastens(done):
                learning.hastened_at = now
        learning.baseline = done.fresh_baseline if policy.fresh_baseline else done.baseline
        learning.next_consolidation = policy.next_after(
            now=now,
            epoch=learning.epoch,
            accepted_at=learning.accepted_at,
            hastened_at=learning.hastened_at,
        )
        return done

    def due_consolidation(self) -> ConsolidationKey | None:
        """The key of the consolidation due now, if one is (:meth:`consolidation_job`);
        of a fleet that learns per type, the first type's in name order."""
        due = self._due_learning()
        return None if due is None else self._key(due)

    def _due_learning(self) -> Learning[P] | None:
        """The learning state whose consolidation is due now, if any."""
        if self.config.consolidation is None or not self._consolidates():
            return None
        for learning in self._learnings():
            if self._clock(learning) >= learning.next_consolidation:
                return learning
        return None

    def scheduled_consolidation(self) -> tuple[int, int] | None:
        """The fleet's target counts at which the next scheduled consolidation falls due
        and by which, solved away from the fleet, it must be applied
        (:meth:`ConsolidationPolicy.apply_by`); ``None`` for a fleet that does not
        consolidate. A type's counts advance with its own targets only, so for a fleet
        that learns per type these are the earliest counts at which any type's could."""
        policy = self.config.consolidation
        if policy is None or not self._consolidates():
            return None
        scheduled = [self._scheduled(learning, policy) for learning in self._learnings()]
        return min(due for due, _ in scheduled), min(by for _, by in scheduled)

    def _scheduled(self, learning: Learning[P], policy: ConsolidationPolicy) -> tuple[int, int]:
        """:meth:`scheduled_consolidation` of one learning state, in the fleet's counts."""
        ahead = self.state.targets - self._clock(learning)
        due = learning.next_consolidation
        apply_by = policy.apply_by(
            due=due,
            epoch=learning.epoch,
            accepted_at=learning.accepted_at,
            hastened_at=learning.hastened_at,
        )
        return due + ahead, apply_by + ahead

    def consolidation_job(self) -> ConsolidationJob[P] | None:
        """The due consolidation's inputs, copied (``None`` when none is due)."""
        due = self._due_learning()
        return None if due is None else self._job(due)

    def _job(self, learning: Learning[P]) -> ConsolidationJob[P]:
        """The inputs of ``learning``'s consolidation, copied; its ``apply_by`` in the
        fleet's counts."""
        policy, state = self.config.consolidation, self.state
        assert policy is not None
        members = learning.vehicles
        return ConsolidationJob(
            key=self._key(learning),
            apply_by=self._scheduled(learning, policy)[1],
            space=cast(SampleSpace[P], self.space),
            positions=tuple(self._group_positions(learning)),
            anchor=tuple(learning.anchor),
            reservoir=tuple(learning.reservoir),
            power=self.config.objective.power,
            speed=float(self._speeds[members[0]]),
            confidence=policy.confidence_at(
                due=learning.next_consolidation, epoch=learning.epoch, fitted=learning.fitted
            ),
            updates=tuple(state.updates[i] for i in members),
            fresh=self._clock(learning) - learning.accepted_at,
            folds=policy.folds,
            refit=policy.refit is not None
            and learning.fitted > 0
            and len(learning.reservoir) >= policy.refit * learning.fitted,
            tested_refit=policy.tested_refit,
            stands=self.config.stands,
            shakes=policy.shakes,
            partners=tuple(learning.partners),
            others=tuple(
                (kind, tuple(self._group_positions(other)), float(self._speeds[other.vehicles[0]]))
                for kind, other in self.state.type_learning.items()
                if other is not learning
            ),
        )

    def _key(self, learning: Learning[P]) -> ConsolidationKey:
        """The key of ``learning``'s consolidation due now (or next): its first vehicle,
        its epoch and the count it falls due at."""
        return (learning.vehicles[0], learning.epoch, learning.next_consolidation)

    def replay_observe(
        self,
        target: P,
        requires: Sequence[str] | None,
        recorded: Consolidation[P] | None,
        recorded_for: Sequence[str] | None = None,
    ) -> Outcome[P]:
        """:meth:`observe` for replay: the consolidation this target triggered is
        ``recorded`` and applied, not solved again; ``recorded_for``, the ids of the
        vehicles it moved (:attr:`Outcome.consolidated`), names the type it is for (needed
        when the target feeds several).

        Raises
        ------
        ReplayMismatch
            A consolidation recorded where the fleet makes none.
        """
        policy = self.config.consolidation
        if policy is None:
            if recorded is not None:
                raise ReplayMismatch("a consolidation was recorded for a fleet that makes none")
            return self.observe(target, requires)
        return self._observe_held(
            policy,
            target,
            requires,
            recorded=recorded,
            recorded_for=None if recorded_for is None else tuple(recorded_for),
            replaying=True,
        )

    @property
    def compiled_update(self) -> bool:
        """Whether a target for any one vehicle goes through the space's compiled update
        (:class:`~routing_svc.sa.space.SingleTargetServing`) rather than its methods."""
        return self._serving() is not None

    def _serving(self) -> SingleTargetServing[P] | None:
        """The space's compiled update for this fleet (kept per space and config), or ``None``."""
        space = self.space
        kept = self._compiled
        if kept is not None and kept[0] is space and kept[1] is self.config:
            return kept[2]
        make = getattr(space, "serving", None)
        window = self.config.probe
        serving: SingleTargetServing[P] | None = None
        if callable(make) and (window is None or (math.isfinite(window) and window > 0.0)):
            probing = window is not None and _is_directed(type(space))
            serving = make(self._speeds, window if probing else 0.0)
        self._compiled = (space, self.config, serving)
        return serving

    def _compiled_search(self, target: P) -> Assignment[P] | None:
        """:meth:`Space.assign` for any one vehicle through the space's compiled update's
        kept columns (:meth:`SingleTargetServing.search`); ``None`` without one, or when
        its search reports an error (the space's own path then raises it)."""
        serving = self._serving()
        if serving is None:
            return None
        return serving.search(target, self.state.positions, self.state.entries)

    def _observe_compiled(self, serving: SingleTargetServing[P], target: P) -> Outcome[P] | None:
        """:meth:`observe` through the space's compiled update; ``None`` if it declined."""
        state = self.state
        gammas = self._step_sizes()
        done = serving.serve(
            target,
            state.positions,
            state.entries,
            gammas,
            self.config.objective.power,
        )
        if done is None:
            return None
        mover = done.mover
        moved = self.vehicles[mover].id
        time = done.completion_time
        dispatch: Dispatch[P] = Dispatch(
            (moved,),
            (time,),
            moved,
            time,
            self.config.objective.cost(time),
            Sent((moved,), ("*",), (time,)),
        )
        index = state.targets
        state.updates[mover] += 1
        state.targets = index + 1
        return Outcome(
            index,
            dispatch,
            float(gammas[mover]),
            done.amount,
            0.0,
            done.old_position,
            done.new_position,
            done.backed_off,
        )

    def _step_sizes(self) -> np.ndarray:
        """Every vehicle's :meth:`step_size`, recomputed only where its count changed."""
        state = self.state
        if self.config.counting is not Counting.VEHICLE:
            return np.full(len(self.vehicles), self.step_size(0))
        kept = self._gammas
        if kept is None or kept[0] is not state or kept[1] is not self.config:
            gammas = np.array([self.step_size(i) for i in range(len(self.vehicles))])
            self._gammas = (state, self.config, list(state.updates), gammas)
            return gammas
        _, _, counts, gammas = kept
        for i in compress(count(), map(ne, state.updates, counts)):
            gammas[i] = self.step_size(i)
            counts[i] = state.updates[i]
        return gammas

    def _probing(self) -> tuple[DirectedSpace[P], float] | None:
        """The space and window of the backward probe, or ``None`` for the paper's rule."""
        window = self.config.probe
        if window is None or not _is_directed(type(self.space)):
            return None
        return cast(DirectedSpace[P], self.space), window

    def _probe(
        self, space: DirectedSpace[P], window: float, target: P, cost: float
    ) -> list[tuple[int, P]]:
        """The backward finite difference of ``J``; the vehicles it moved, with where to.

        The paper's step follows the gradient of the smooth part of ``J`` and
        misses its jump term (see :class:`DirectedSpace`). This estimates it. The
        target is also served, in one search, from one probe per vehicle: the
        point ``h`` behind its reference on its edge or, on a shorter stretch, the
        junction behind it whose turns it gave up (:attr:`FleetState.entries`).
        With ``c_j`` the probe's time and ``cost`` the fleet's, moving a vehicle
        ``j`` that does not serve the target back to its probe changes the cost
        of this target by ``-G_j = min(0, c_j - cost)``: a sample of the backward
        difference ``J(x - h e_j) - J(x)``, whose jump part the paper's step
        misses. Each ``j`` with ``G_j > 0`` moves ``min(h, gamma_j G_j / h)``
        back toward its probe (never past it); a moved mover makes no forward
        step for this target. The paper's step supplies the forward (smooth)
        part of the gradient, the probe the backward jump.
        """
        positions, entries = self.state.positions, self.state.entries
        probes = self._back_probes(space, window)
        # only a probe that arrives before the fleet matters: the search stops there
        times = space.arrival_times(target, probes, self._speeds, cost)
        backed_off: list[tuple[int, P]] = []
        for j, arrival in enumerate(times.tolist()):
            if not probe_gains(arrival, cost):
                continue
            amount = probe_step(self.step_size(j), cost - arrival, window)
            moved = space.back_off(positions[j], probes[j], amount)
            entries[j] = space.entry(positions[j], moved, None, entries[j], window)
            positions[j] = moved
            backed_off.append((j, moved))
        return backed_off

    def _back_probes(self, space: DirectedSpace[P], window: float) -> list[P]:
        """``space.back_probes`` of the current references, recomputed only for the
        vehicles whose reference or entry changed since the last call.

        The list returned is the cache's own (the same object from call to call,
        which lets the space keep its search columns): callers only read it.
        """
        positions, entries = self.state.positions, self.state.entries
        cache = self._probe_cache
        if cache is None or cache.space is not space or cache.window != window:
            probes = space.back_probes(positions, window, entries)
            self._probe_cache = _ProbeCache(space, window, list(positions), list(entries), probes)
            return probes
        changed = set(compress(count(), map(is_not, positions, cache.positions)))
        changed.update(compress(count(), map(is_not, entries, cache.entries)))
        for j in sorted(changed):
            position, entry = positions[j], entries[j]
            (cache.probes[j],) = space.back_probes([position], window, [entry])
            cache.positions[j], cache.entries[j] = position, entry
        return cache.probes

    def snapshot(self) -> dict[str, Any]:
        """JSON-ready state (floats round-trip exactly through ``json``)."""
        return {
            "positions": self.space.encode_many(self.state.positions),
            "updates": list(self.state.updates),
            "targets": self.state.targets,
            "entries": [None if e is None else self.space.encode(e) for e in self.state.entries],
            **({} if self.state.learning is None else {"learning": self._learning_dict()}),
            **(
                {
                    "type_learning": {
                        kind: self._learning_dict(learning)
                        for kind, learning in self.state.type_learning.items()
                    }
                }
                if self.state.type_learning
                else {}
            ),
            **({} if self._states_default() else {"vehicle_states": self._states_list()}),
        }

    def _states_default(self) -> bool:
        return all(s.is_default for s in self.state.vehicle_states)

    def _states_list(self) -> list[dict[str, Any]]:
        encode = self.space.encode
        return [
            {
                "status": s.status.value,
                "position": None if s.position is None else encode(s.position),
                "timestamp": s.timestamp,
            }
            for s in self.state.vehicle_states
        ]

    def _learning_dict(self, learning: Learning[P] | None = None) -> dict[str, Any]:
        """One learning state as JSON (the whole fleet's by default); a type's also
        has its count ``seen``."""
        learning = self.state.learning if learning is None else learning
        policy = self.config.consolidation
        assert learning is not None and policy is not None
        encode = self.space.encode
        return {
            "holds": [
                None if h is None else {"exit": encode(h.exit), "pressure": h.pressure}
                for h in learning.holds
            ],
            "anchor": self.space.encode_many(learning.anchor),
            "reservoir": self.space.encode_many(learning.reservoir),
            "epoch": learning.epoch,
            "next_consolidation": learning.next_consolidation,
            "baseline": learning.baseline,
            "accepted_at": learning.accepted_at,
            "block_cost": learning.block_cost,
            "block_size": learning.block_size,
            **(
                {"fitted": learning.fitted}
                if policy.refit is not None or policy.unfitted_confidence
                else {}
            ),
            **(
                {"block_squares": learning.block_squares, "run": list(learning.run)}
                if policy.shift_confidence
                else {}
            ),
            **({"hastened_at": learning.hastened_at} if policy.hasten is not None else {}),
            **(
                {
                    "served": None if learning.served is None else list(learning.served),
                    "wins": list(learning.wins),
                }
                if self._tests_winners()
                else {}
            ),
            **({} if self._type_groups is None else {"seen": learning.seen}),
            **(
                {"partners": [list(kinds) for kinds in learning.partners]}
                if any(learning.partners)
                else {}
            ),
        }

    def _learning_from(
        self, data: dict[str, Any], members: tuple[int, ...] | None = None
    ) -> Learning[P]:
        """:meth:`_learning_dict` read back, for the vehicles ``members`` (default: all)."""
        policy = self.config.consolidation
        if policy is None:
            raise InvalidInput("snapshot has learning state for a fleet without the rule")
        decode = self.space.decode
        if members is None:
            members = tuple(range(len(self.vehicles)))
        n = len(members)
        holds: list[Hold[P] | None] = [
            None if h is None else Hold(decode(h["exit"]), float(h["pressure"]))
            for h in data["holds"]
        ]
        anchor = [decode(p) for p in data["anchor"]]
        if len(holds) != n or len(anchor) != n:
            raise InvalidInput("snapshot does not match the fleet's vehicles")
        baseline = data["baseline"]
        partners = [tuple(str(k) for k in kinds) for kinds in data.get("partners", ())]
        if "partners" not in data:  # a snapshot without them: no target needed another type
            partners = [() for _ in data["reservoir"]]
        if len(partners) != len(data["reservoir"]):
            raise InvalidInput("snapshot's partners do not match its reservoir")
        served = data.get("served")
        wins = [int(w) for w in data.get("wins", ())]
        if (served is not None and len(served) != n) or (
            wins and (served is None or len(wins) != n)
        ):
            raise InvalidInput("snapshot's winners do not match the fleet's vehicles")
        return Learning(
            holds=holds,
            anchor=anchor,
            reservoir=deque((decode(p) for p in data["reservoir"]), maxlen=policy.reservoir),
            partners=deque(partners, maxlen=policy.reservoir),
            epoch=int(data["epoch"]),
            next_consolidation=int(data["next_consolidation"]),
            baseline=None if baseline is None else float(baseline),
            accepted_at=int(data["accepted_at"]),
            block_cost=float(data["block_cost"]),
            block_size=int(data["block_size"]),
            block_squares=float(data.get("block_squares", 0.0)),
            run=_run_of(data.get("run", [0.0, 0.0, 0])),
            fitted=int(data.get("fitted", 0)),
            hastened_at=int(data.get("hastened_at", 0)),
            vehicles=members,
            seen=int(data.get("seen", 0)),
            served=None if served is None else tuple(int(c) for c in served),
            wins=wins,
            won=sum(wins),
        )

    def restore(self, data: dict[str, Any]) -> None:
        """Load a :meth:`snapshot` taken from a fleet with the same vehicles."""
        positions = [self.space.decode(p) for p in data["positions"]]
        updates = [int(u) for u in data["updates"]]
        if len(positions) != len(self.vehicles) or len(updates) != len(self.vehicles):
            raise InvalidInput("snapshot does not match the fleet's vehicles")
        raw = data.get("entries") or [None] * len(positions)
        entries = [None if e is None else self.space.decode(e) for e in raw]
        if len(entries) != len(positions):
            raise InvalidInput("snapshot does not match the fleet's vehicles")
        learning = None
        type_learning: dict[str, Learning[P]] = {}
        groups = self._type_groups
        if self.config.consolidation is not None and groups is None:
            if "learning" not in data:
                raise InvalidInput("snapshot lacks the consolidating rule's state")
            learning = self._learning_from(data["learning"])
        elif self.config.consolidation is not None and groups is not None:
            stored = data.get("type_learning")
            if not isinstance(stored, dict) or sorted(stored) != list(groups):
                raise InvalidInput("snapshot lacks the consolidating rule's state per type")
            type_learning = {
                kind: self._learning_from(stored[kind], members) for kind, members in groups.items()
            }
        states: list[VehicleState[P]] = [
            VehicleState(
                Status(s["status"]),
                None if s["position"] is None else self.space.decode(s["position"]),
                None if s["timestamp"] is None else float(s["timestamp"]),
            )
            for s in data.get("vehicle_states", ())
        ]
        if states and len(states) != len(positions):
            raise InvalidInput("snapshot does not match the fleet's vehicles")
        self.state = FleetState(
            positions,
            updates,
            int(data["targets"]),
            entries,
            learning,
            states or [VehicleState() for _ in positions],
            type_learning,
        )

    def vehicle_index(self, vehicle_id: str) -> int:
        """Index of a vehicle by id (vehicles are sorted by id)."""
        try:
            return self._index[vehicle_id]
        except KeyError:
            raise NotFound(f"unknown vehicle {vehicle_id!r}") from None


def type_groups(types: Sequence[str], speeds: Sequence[float]) -> dict[str, tuple[int, ...]] | None:
    """Each type's vehicles (indices), types in name order, when every type's vehicles
    share one speed; else ``None`` (such a type cannot consolidate as one p-median)."""
    groups: dict[str, list[int]] = {}
    for i, kind in enumerate(types):
        groups.setdefault(kind, []).append(i)
    if any(len({float(speeds[i]) for i in members}) > 1 for members in groups.values()):
        return None
    return {kind: tuple(members) for kind, members in sorted(groups.items())}


def can_consolidate(types: Sequence[str], speeds: Sequence[float], *, stands: bool) -> bool:
    """Whether a fleet of these vehicles learns by consolidations under ``consolidating``
    (with :attr:`FleetConfig.per_type`): one speed per type, and, with several types,
    no stands (:attr:`Fleet.learns_per_type`)."""
    groups = type_groups(types, speeds)
    return groups is not None and (len(groups) == 1 or not stands)


def prior_counts(
    space: Space[P], positions: Sequence[P], speeds: Sequence[float], sample: Sequence[P]
) -> tuple[int, ...]:
    """How many targets of ``sample`` each vehicle serves from ``positions``.

    Each target goes to the vehicle that reaches it first, exactly as
    :meth:`Fleet.assign` chooses for a target that needs one vehicle (ties by
    the lower index). ``positions`` and ``speeds`` are in the fleet's id order;
    the result is :attr:`FleetConfig.prior_counts`.
    """
    n = len(positions)
    anyone = Requirement(np.zeros(n, dtype=np.int64), np.ones(1, dtype=np.int64))
    velocities = np.asarray(speeds, dtype=np.float64)
    counts = [0] * n
    for target in sample:
        counts[space.assign(target, list(positions), velocities, anyone).mover] += 1
    return tuple(counts)


@functools.cache
def _offers(kind: type, *methods: str) -> bool:
    """Whether spaces of class ``kind`` have every one of ``methods`` (checked once per
    class and protocol: a runtime protocol check inspects every method)."""
    return all(callable(getattr(kind, name, None)) for name in methods)


def _has_junctions(kind: type) -> bool:
    """Whether spaces of class ``kind`` are :class:`JunctionSpace` s."""
    return _offers(kind, "junction_ahead", "advance")


def _samples(kind: type) -> bool:
    """Whether spaces of class ``kind`` are :class:`SampleSpace` s."""
    return _offers(kind, "candidate_references", "cost_matrix")


def _is_directed(kind: type) -> bool:
    """Whether spaces of class ``kind`` are :class:`DirectedSpace` s."""
    return _offers(kind, "back_probes", "arrival_times", "back_off", "entry")


Solved = tuple[ConsolidationKey, Consolidation[P]]
"""A consolidation solved away from the fleet, with the key of the job it answers."""


def _new_epoch(learning: Learning[P], policy: ConsolidationPolicy, now: int) -> None:
    """Start a new epoch of ``learning`` at its count ``now`` (a shift test found that
    the demand moved): the reservoir keeps its last block, the schedule starts again and
    nothing of the demand before is expected."""
    learning.run = NO_SHIFT_RUN
    recent = list(learning.reservoir)[-policy.block :]
    learning.reservoir.clear()
    learning.reservoir.extend(recent)
    kept = list(learning.partners)[-policy.block :]
    learning.partners.clear()
    learning.partners.extend(kept)
    learning.epoch = now
    learning.next_consolidation = now + policy.first
    learning.baseline = None
    learning.fitted = 0
    learning.served, learning.wins, learning.won = None, [], 0


def _run_of(data: Any) -> ShiftRun:
    """A stored run of the shift test (``[cost sum, square sum, size]``)."""
    if not isinstance(data, list) or len(data) != 3:
        raise InvalidInput("snapshot's shift-test run must be [cost sum, square sum, size]")
    return float(data[0]), float(data[1]), int(data[2])
