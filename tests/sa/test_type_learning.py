"""A fleet of several types learns per type (:attr:`Fleet.learns_per_type`).

The reference is the decomposition itself: one consolidating fleet per type, each
fed the targets that needed its type, with the same settings.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
from collections.abc import Sequence

import numpy as np
import pytest

from routing_svc.demand.network import hotspot_mixture
from routing_svc.errors import InvalidInput, ReplayMismatch
from routing_svc.network import RoadSpace, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.optimum import expected_cost, solve_demand
from routing_svc.sa import (
    ROUTING,
    Consolidation,
    ConsolidationPolicy,
    Fleet,
    FleetConfig,
    Status,
    Vehicle,
    VehicleState,
    learning_config,
)
from routing_svc.sa.consolidation import ANY_VEHICLE
from routing_svc.sa.fleet import can_consolidate, type_groups
from routing_svc.types import NetPosition

NET = load_network(resolve_network("drt"))
POLICY = ConsolidationPolicy(reservoir=400, first=50, growth=1.25, longest=100, block=50)
TYPES = {"A": 3, "B": 2}
Stream = list[tuple[NetPosition, list[str] | None]]


@pytest.fixture(scope="module")
def space() -> RoadSpace:
    return RoadSpace(NET, cost="length")


@pytest.fixture(scope="module")
def config(space: RoadSpace) -> FleetConfig:
    return learning_config(
        "consolidating",
        typical_cost=space.typical_cost(),
        n_vehicles=sum(TYPES.values()),
        objective=ROUTING,
        consolidation=POLICY,
    )


def starts(kind: str) -> list[tuple[Vehicle, NetPosition]]:
    """The vehicles of ``kind`` and their starting references (all on a few edges)."""
    offset = 0 if kind == "A" else 7
    return [
        (Vehicle(f"{kind}{i}", kind), NetPosition(offset + 11 * i, 0.0)) for i in range(TYPES[kind])
    ]


def of_type(references: dict[str, NetPosition], kind: str) -> list[NetPosition]:
    """The references of the vehicles of ``kind`` (their ids begin with it)."""
    return [p for vid, p in references.items() if vid.startswith(kind)]


def typed_fleet(space: RoadSpace, config: FleetConfig) -> Fleet[NetPosition]:
    return Fleet.create(space, starts("A") + starts("B"), config)


def stream(seed: int, n: int, mixed: float = 0.0) -> Stream:
    """``n`` targets of a three-hotspot demand; each needs one A or one B (even odds),
    or, with probability ``mixed``, any one vehicle or an A and a B."""
    demand = hotspot_mixture(NET, centres=3, rng=np.random.default_rng(100 + seed))
    rng = np.random.default_rng(seed)
    targets = demand.sample(rng, n)
    out: Stream = []
    for z in targets:
        if rng.random() < mixed:
            out.append((z, None if rng.random() < 0.5 else ["A", "B"]))
        else:
            out.append((z, ["A" if rng.random() < 0.5 else "B"]))
    return out


def test_a_fleet_of_types_with_one_speed_each_learns_per_type(
    space: RoadSpace, config: FleetConfig
) -> None:
    fleet = typed_fleet(space, config)
    assert fleet.learns_per_type
    assert fleet.state.learning is None
    assert list(fleet.state.type_learning) == ["A", "B"]
    assert fleet.state.type_learning["A"].vehicles == (0, 1, 2)
    assert fleet.state.type_learning["B"].vehicles == (3, 4)
    mixed_speeds = [*starts("A"), (Vehicle("B0", "B", speed=1.0), NetPosition(7, 0.0))]
    mixed_speeds.append((Vehicle("B1", "B", speed=2.0), NetPosition(18, 0.0)))
    assert not Fleet.create(space, mixed_speeds, config).learns_per_type
    identical = Fleet.create(space, [(Vehicle(v.id), p) for v, p in starts("A")], config)
    assert not identical.learns_per_type and identical.state.learning is not None


def test_targets_of_one_type_learn_exactly_as_one_fleet_per_type(
    space: RoadSpace, config: FleetConfig
) -> None:
    fleet = typed_fleet(space, config)
    alone = {kind: Fleet.create(space, starts(kind), config) for kind in TYPES}
    made = {kind: 0 for kind in TYPES}
    for z, requires in stream(3, 1400):
        assert requires is not None
        (kind,) = requires
        out = fleet.observe(z, requires)
        ref = alone[kind].observe(z)
        assert out.dispatch.moved == ref.dispatch.moved
        assert out.new_position == ref.new_position
        assert out.consolidation == ref.consolidation
        made[kind] += out.consolidation is not None
    assert min(made.values()) >= 4  # several consolidations of each type were compared
    assert fleet.positions == {**alone["A"].positions, **alone["B"].positions}
    for kind, learning in fleet.state.type_learning.items():
        assert learning.seen == alone[kind].state.targets
        assert list(learning.reservoir) == list(alone[kind].state.learning.reservoir)  # type: ignore[union-attr]


@pytest.mark.parametrize("shared", [True, False])
def test_a_target_feeds_each_type_it_needs_and_one_for_any_vehicle_all_or_none(
    space: RoadSpace, config: FleetConfig, shared: bool
) -> None:
    """A target for any one vehicle feeds every type (``shared_targets``, the default),
    kept with :data:`ANY_VEHICLE` as its partners; under a policy stored before, none."""
    policy = dataclasses.replace(POLICY, shared_targets=shared)
    fleet = typed_fleet(space, dataclasses.replace(config, consolidation=policy))
    targets = stream(4, 900, mixed=0.4)
    for z, requires in targets:
        fleet.observe(z, requires)
    for kind, learning in fleet.state.type_learning.items():
        own = [(z, r) for z, r in targets if (r is None and shared) or (r and kind in r)]
        assert learning.seen == len(own) < len(targets)
        assert list(learning.reservoir) == [z for z, _ in own][-POLICY.reservoir :]
        other = [k for k in TYPES if k != kind]
        partners = [ANY_VEHICLE if r is None else tuple(k for k in other if k in r) for _, r in own]
        assert list(learning.partners) == partners[-POLICY.reservoir :]
    assert fleet.state.targets == len(targets)


def test_a_target_of_several_types_tests_each_at_its_last_arrival(
    space: RoadSpace, config: FleetConfig
) -> None:
    fleet = typed_fleet(space, config)
    (z, _), *_ = stream(10, 1)
    references = dict(fleet.positions)
    fleet.observe(z, ["A", "B"])
    closest = {
        kind: float(space.cost_matrix(of_type(references, kind), [z]).min()) for kind in TYPES
    }
    assert closest["A"] != closest["B"]
    for kind, learning in fleet.state.type_learning.items():
        assert learning.block_size == 1
        assert learning.block_cost == pytest.approx(ROUTING.cost(max(closest.values())), rel=1e-12)
        assert list(learning.partners) == [tuple(k for k in TYPES if k != kind)]


def test_a_consolidation_prices_targets_by_the_other_types_references(
    space: RoadSpace, config: FleetConfig
) -> None:
    """A target that needed the other type too costs at least its last arrival (floor),
    one for any vehicle at most the other type's first arrival (ceiling), each by hand."""
    fleet = typed_fleet(space, config)
    fleet.defer_consolidations = True
    targets = stream(12, 400, mixed=0.5)
    job = None
    for z, r in targets:
        fleet.observe(z, r)
        job = job or fleet.consolidation_job()
    assert job is not None
    kind, other = ("A", "B") if job.key[0] == 0 else ("B", "A")
    mine = [(z, r) for z, r in targets if r is None or kind in r][: len(job.reservoir)]
    assert list(job.reservoir) == [z for z, _ in mine]
    assert list(job.partners) == [
        ANY_VEHICLE if r is None else ((other,) if other in r else ()) for _, r in mine
    ]
    assert {ANY_VEHICLE, (other,), ()} == set(job.partners)
    (named, references, speed), *rest = job.others
    assert named == other and not rest and speed == 1.0
    assert references == tuple(of_type(fleet.positions, other))
    floors, ceilings = job.floors(), job.ceilings()
    assert floors is not None and ceilings is not None
    for z, partners, floor, ceiling in zip(
        job.reservoir, job.partners, floors, ceilings, strict=True
    ):
        by_hand = ROUTING.cost(min(float(space.cost_matrix([p], [z])[0, 0]) for p in references))
        assert floor == (pytest.approx(by_hand, rel=1e-12) if partners == (other,) else 0.0)
        assert ceiling == (pytest.approx(by_hand, rel=1e-12) if partners == ANY_VEHICLE else np.inf)
    assert job.solve() == dataclasses.replace(job).solve()  # deterministic
    only_mine = dataclasses.replace(job, partners=tuple(() for _ in job.partners))
    assert only_mine.floors() is None and only_mine.ceilings() is None


def test_one_consolidation_a_target_the_other_type_stays_due(
    space: RoadSpace, config: FleetConfig
) -> None:
    fleet = typed_fleet(space, config)
    both = [(z, ["A", "B"]) for z, _ in stream(11, POLICY.first + 1)]
    outcomes = [fleet.observe(z, r) for z, r in both]
    made = [(o.target_number, o.consolidated) for o in outcomes if o.consolidation is not None]
    # both types fall due at the 50th target: A (first by name) then, one target later, B
    assert made == [(POLICY.first - 1, ("A0", "A1", "A2")), (POLICY.first, ("B0", "B1"))]
    replayed = typed_fleet(space, config)
    for (z, r), o in zip(both, outcomes, strict=True):
        replayed.replay_observe(z, r, o.consolidation, o.consolidated or None)
    assert replayed.snapshot() == fleet.snapshot()
    # the vehicles a recorded consolidation moved decide its type; they must be given
    again = typed_fleet(space, config)
    for (z, r), o in zip(both[:-2], outcomes, strict=False):
        again.replay_observe(z, r, o.consolidation)
    with pytest.raises(ReplayMismatch, match="names no vehicles"):
        again.replay_observe(both[-2][0], ["A", "B"], outcomes[-2].consolidation)


Recorded = list[tuple[Consolidation[NetPosition] | None, tuple[str, ...] | None]]


def run(fleet: Fleet[NetPosition], targets: Stream) -> Recorded:
    """Every target's consolidation and the vehicles it moved."""
    outcomes = [fleet.observe(z, r) for z, r in targets]
    return [(o.consolidation, o.consolidated or None) for o in outcomes]


def test_each_types_posts_are_chosen_on_the_targets_that_needed_it(
    space: RoadSpace, config: FleetConfig
) -> None:
    # A's targets (some with a B) around one hotspot, twice as many B's around another
    rng = np.random.default_rng(4)
    near_a = hotspot_mixture(NET, centres=1, rng=np.random.default_rng(204))
    near_b = hotspot_mixture(NET, centres=1, rng=np.random.default_rng(304))
    targets: Stream = [(z, ["A"]) for z in near_a.sample(rng, 60)]
    targets += [(z, ["B"]) for z in near_b.sample(rng, 120)]
    targets += [(z, ["A", "B"]) for z in near_a.sample(rng, 20)]
    fleet = typed_fleet(space, config)
    run(fleet, targets)
    fleet.set_states([("A0", VehicleState(Status.BUSY)), ("B0", VehicleState(Status.BUSY))])
    posts = fleet.posts()

    def best(kind: str, free: int, sample: list[NetPosition]) -> set[NetPosition]:
        """By enumeration: the ``free`` references of ``kind`` that serve ``sample`` best."""
        mine = of_type(fleet.positions, kind)
        subsets = itertools.combinations(mine, free)
        return set(
            min(subsets, key=lambda s: float(space.cost_matrix(list(s), sample).min(axis=0).sum()))
        )

    needed = {kind: [z for z, r in targets if r is not None and kind in r] for kind in TYPES}
    for kind, free in (("A", 2), ("B", 1)):
        chosen = {p.position for p in posts if fleet.vehicles[p.vehicle].type == kind}
        assert chosen == best(kind, free, needed[kind])
    # on every target, A's posts would be others: B's demand would pull them away
    assert best("A", 2, needed["A"]) != best("A", 2, [z for z, _ in targets])


def test_snapshot_and_restore_go_on_as_if_never_stopped(
    space: RoadSpace, config: FleetConfig
) -> None:
    targets = stream(5, 1200, mixed=0.2)
    whole = typed_fleet(space, config)
    run(whole, targets)
    first = typed_fleet(space, config)
    run(first, targets[:700])
    saved = json.loads(json.dumps(first.snapshot()))
    assert set(saved["type_learning"]) == {"A", "B"} and "learning" not in saved
    second = typed_fleet(space, config)
    second.restore(saved)
    run(second, targets[700:])
    assert second.positions == whole.positions
    assert second.snapshot() == whole.snapshot()
    assert any(saved["type_learning"]["A"]["partners"])
    older = json.loads(json.dumps(saved))  # a snapshot from before the partners were kept
    for kept in older["type_learning"].values():
        del kept["partners"]
    third = typed_fleet(space, config)
    third.restore(older)
    for learning in third.state.type_learning.values():
        assert list(learning.partners) == [()] * len(learning.reservoir)
    saved["type_learning"]["B"]["partners"].pop()
    with pytest.raises(InvalidInput, match="partners"):
        typed_fleet(space, config).restore(saved)
    del saved["type_learning"]
    with pytest.raises(InvalidInput, match="per type"):
        typed_fleet(space, config).restore(saved)


def test_replay_applies_the_recorded_consolidations_and_checks_where(
    space: RoadSpace, config: FleetConfig
) -> None:
    targets = stream(6, 1000, mixed=0.2)
    live = typed_fleet(space, config)
    recorded = run(live, targets)
    assert sum(c is not None for c, _ in recorded) >= 6
    replayed = typed_fleet(space, config)
    for (z, r), (done, moved) in zip(targets, recorded, strict=True):
        replayed.replay_observe(z, r, done, moved)
    assert replayed.snapshot() == live.snapshot()
    # a consolidation recorded at a target where none was due is refused
    first = next(c for c, _ in recorded if c is not None)
    z, r = targets[0]
    with pytest.raises(ReplayMismatch, match="none was due"):
        typed_fleet(space, config).replay_observe(z, r, first)


def test_deferred_solves_are_keyed_by_type_and_replay_the_same(
    space: RoadSpace, config: FleetConfig
) -> None:
    targets = stream(7, 1000, mixed=0.2)
    deferred = typed_fleet(space, config)
    recorded: Recorded = []
    deferred.defer_consolidations = True
    keys: list[tuple[int, int, int]] = []
    for z, r in targets:
        job = deferred.consolidation_job()
        solved = None
        if job is not None:
            if not keys or keys[-1] != job.key:
                keys.append(job.key)
            solved = (job.key, job.solve())
            scheduled = deferred.scheduled_consolidation()
            assert scheduled is not None and scheduled[0] <= deferred.state.targets
        out = deferred.observe(z, r, solved=solved)
        recorded.append((out.consolidation, out.consolidated or None))
    firsts = {key[0] for key in keys}
    assert firsts == {0, 3}  # jobs of both types: keyed by each type's first vehicle
    assert sum(c is not None for c, _ in recorded) >= len(keys) - 2
    replayed = typed_fleet(space, config)
    for (z, r), (done, moved) in zip(targets, recorded, strict=True):
        replayed.replay_observe(z, r, done, moved)
    assert replayed.snapshot() == deferred.snapshot()


def test_the_schedule_is_the_earliest_of_the_types_in_the_fleets_counts(
    space: RoadSpace, config: FleetConfig
) -> None:
    fleet = typed_fleet(space, config)
    assert fleet.scheduled_consolidation() == (POLICY.first, POLICY.first + apply_lag(fleet))
    targets: Sequence[tuple[NetPosition, list[str] | None]] = stream(8, 30, mixed=0.5)
    for z, r in targets:
        fleet.observe(z, r)
    counts = {k: learning.seen for k, learning in fleet.state.type_learning.items()}
    due, _ = fleet.scheduled_consolidation() or (0, 0)
    assert due == len(targets) + POLICY.first - max(counts.values())


def apply_lag(fleet: Fleet[NetPosition]) -> int:
    """How long after falling due a fresh type's first consolidation may be applied."""
    learning = fleet.state.type_learning["A"]
    return (
        POLICY.apply_by(
            due=learning.next_consolidation,
            epoch=learning.epoch,
            accepted_at=learning.accepted_at,
            hastened_at=learning.hastened_at,
        )
        - learning.next_consolidation
    )


def test_a_stored_config_keeps_the_learning_it_was_created_with(
    space: RoadSpace, config: FleetConfig
) -> None:
    stored = json.loads(json.dumps(config.to_dict()))
    assert stored["per_type"] is True
    assert typed_fleet(space, FleetConfig.from_dict(stored)).learns_per_type
    del stored["per_type"]  # stored before a fleet of several types learned per type
    before = FleetConfig.from_dict(stored)
    assert before.to_dict() == stored
    fleet = typed_fleet(space, before)
    assert not fleet.learns_per_type and fleet.state.learning is not None
    for z, requires in stream(9, 400):
        assert fleet.observe(z, requires).consolidation is None  # held steps only, as then
    with pytest.raises(InvalidInput, match="per type"):
        FleetConfig(objective=ROUTING, schedule=config.schedule, per_type=True)


def test_which_fleets_can_consolidate() -> None:
    assert can_consolidate(["a", "a"], [1.0, 1.0], stands=True)  # identical, stands or not
    assert can_consolidate(["a", "b"], [1.0, 2.0], stands=False)  # one speed per type
    assert not can_consolidate(["a", "b"], [1.0, 2.0], stands=True)  # types share stands
    assert not can_consolidate(["a", "a", "b"], [1.0, 2.0, 1.0], stands=False)
    assert type_groups(["b", "a", "b"], [1.0, 1.0, 1.0]) == {"a": (1,), "b": (0, 2)}


@pytest.mark.parametrize("seed", [0, 1])
def test_targets_for_any_vehicle_lead_a_typed_fleet_to_the_p_median_of_all_its_vehicles(
    space: RoadSpace, config: FleetConfig, seed: int
) -> None:
    """Of targets that each need any one vehicle, objective (11) is the p-median of all
    the fleet's vehicles (one speed): the types learn it together, each fitting what the
    other's references leave; under a policy stored before, no type learns from them."""
    demand = hotspot_mixture(NET, centres=3, rng=np.random.default_rng(100 + seed))
    n = sum(TYPES.values())
    optimum = solve_demand(space, demand, n).objective
    targets = demand.sample(np.random.default_rng(seed), 1500)
    gaps = {}
    for shared in (True, False):
        policy = dataclasses.replace(POLICY, shared_targets=shared)
        fleet = typed_fleet(space, dataclasses.replace(config, consolidation=policy))
        for z in targets:
            fleet.observe(z, None)
        value = expected_cost(space, list(fleet.state.positions), np.ones(n), demand)
        gaps[shared] = value / optimum - 1.0
    assert gaps[True] < 0.03
    assert gaps[False] > 0.5  # the start, about where it was
