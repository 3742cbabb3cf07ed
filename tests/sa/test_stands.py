"""Learning between stands: each vehicle's stand, the capacitated fill, a consolidation over
stands against enumeration, and a fleet's stands through its config and its learning."""

from __future__ import annotations

import itertools
import json
import math
from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

from routing_svc.demand.network import hotspot_mixture
from routing_svc.errors import InvalidInput
from routing_svc.network import RoadSpace, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.sa import Fleet, FleetConfig, Objective, Vehicle, learning_config
from routing_svc.sa.consolidation import consolidate
from routing_svc.sa.stands import StandSet, fill_capacity, stand_assignment, vehicle_stands
from routing_svc.types import FloatArray, IntArray, NetPosition

NET = load_network(resolve_network("drt"))
SPACE = RoadSpace(NET, cost="length")


def nearest_pairs_first(costs: FloatArray, capacities: list[int]) -> list[int]:
    """The rule spelt out: again and again, the cheapest pair of a vehicle without a stand
    and a stand with room (ties: lower stand, then lower vehicle)."""
    n_stands, n_vehicles = costs.shape
    free, stand = list(capacities), [-1] * n_vehicles
    for _ in range(n_vehicles):
        pairs = [
            (float(costs[i, k]), i, k)
            for i in range(n_stands)
            for k in range(n_vehicles)
            if stand[k] < 0 and free[i] > 0
        ]
        _, i, k = min(pairs)
        stand[k], free[i] = i, free[i] - 1
    return stand


def test_a_vehicle_takes_the_nearest_stand_with_room_by_hand() -> None:
    costs = np.array([[1.0, 2.0, 9.0], [5.0, 3.0, 8.0], [7.0, 6.0, 4.0]])
    # vehicle 0 is nearest stand 0 and takes it; vehicle 1 would take stand 0 too, which
    # is full, so it takes stand 1; vehicle 2 takes stand 2
    assert stand_assignment(costs, [1, 1, 1]).tolist() == [0, 1, 2]
    assert stand_assignment(costs, [2, 1, 1]).tolist() == [0, 0, 2]
    assert stand_assignment(costs, [3, 0, 0]).tolist() == [0, 0, 0]
    with pytest.raises(InvalidInput, match="fewer vehicles"):
        stand_assignment(costs, [1, 1, 0])


@pytest.mark.parametrize("seed", range(20))
def test_the_stand_assignment_against_the_rule_spelt_out(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_stands, n_vehicles = int(rng.integers(1, 7)), int(rng.integers(1, 9))
    costs = rng.integers(0, 6, size=(n_stands, n_vehicles)).astype(np.float64)  # many ties
    capacities = rng.integers(1, 4, size=n_stands).tolist()
    while sum(capacities) < n_vehicles:
        capacities[int(rng.integers(n_stands))] += 1
    found = stand_assignment(costs, capacities).tolist()
    assert found == nearest_pairs_first(costs, capacities)
    assert all(Counter(found)[i] <= c for i, c in enumerate(capacities))


def test_the_fill_by_hand() -> None:
    served = np.array([0.1, 0.5, 0.4])
    assert fill_capacity([2, 0], [1, 1, 1], 2, served).tolist() == [0, 2]
    # three more vehicles than open stands: round the stands by served weight, where room is
    assert fill_capacity([0, 1, 2], [1, 3, 3], 6, served).tolist() == [0, 1, 1, 1, 2, 2]
    with pytest.raises(InvalidInput):
        fill_capacity([0], [1, 1, 1], 4, served)


def test_a_stand_set() -> None:
    a, b = NetPosition(1, 0.0), NetPosition(2, 1.0)
    merged = StandSet.merged([(a, 1), (b, 2), (a, 3)])
    assert merged == StandSet((a, b), (4, 2))
    assert merged.capacity == 6
    merged.check_fleet(6)
    with pytest.raises(InvalidInput, match="7 vehicles exceed"):
        merged.check_fleet(7)
    for bad in [((a, a), (1, 1)), ((a,), (0,)), ((a,), (True,)), ((), ()), ((a, b), (1,))]:
        with pytest.raises(InvalidInput):
            StandSet(*bad)
    stored = merged.to_dict(SPACE.encode)
    assert stored[0] == {**SPACE.encode(a), "capacity": 4}
    assert StandSet.from_dict(json.loads(json.dumps(stored)), SPACE.decode) == merged


def random_stands(seed: int, capacities: tuple[int, ...]) -> StandSet[NetPosition]:
    rng = np.random.default_rng(seed)
    edges = rng.choice(NET.n_edges, size=len(capacities), replace=False)
    return StandSet(tuple(NetPosition(int(e), 0.0) for e in edges), capacities)


def reservoir_cost(rows: tuple[int, ...] | IntArray, costs: FloatArray) -> float:
    return math.fsum(costs[list(rows)].min(axis=0).tolist())


@pytest.mark.parametrize(
    ("capacities", "p"), [((1, 1, 1, 1, 1, 1), 2), ((2, 1, 1, 1, 2), 3), ((2, 1, 2), 4)]
)
def test_a_consolidation_over_stands_against_enumeration(
    capacities: tuple[int, ...], p: int
) -> None:
    demand = hotspot_mixture(NET, centres=2, rng=np.random.default_rng(7))
    reservoir = demand.sample(np.random.default_rng(8), 60)
    stands = random_stands(9, capacities)
    costs = SPACE.cost_matrix(list(stands.positions), reservoir)
    rows_fit = [
        rows
        for rows in itertools.combinations_with_replacement(range(len(capacities)), p)
        if all(k <= capacities[i] for i, k in Counter(rows).items())
    ]
    best = min(reservoir_cost(rows, costs) for rows in rows_fit)
    worst = max(rows_fit, key=lambda rows: reservoir_cost(rows, costs))
    start = [stands.positions[i] for i in worst]
    done = consolidate(
        SPACE, start, start, reservoir, power=1.0, speed=1.0, confidence=0.0,
        updates=[0] * p, fresh=len(reservoir), stands=stands,
    )  # fmt: skip
    assert done.accepted
    assert set(done.positions) <= set(stands.positions)
    counts = Counter(done.positions)
    assert all(counts[x] <= c for x, c in zip(stands.positions, stands.capacities, strict=True))
    rows = tuple(stands.positions.index(x) for x in done.positions)
    assert reservoir_cost(rows, costs) == pytest.approx(best, rel=1e-12)
    # the cost before is that of the vehicles' stands, here their references
    assert done.sample_before == pytest.approx(reservoir_cost(worst, costs) / len(reservoir))
    # a vehicle whose stand stays open keeps it
    kept = Counter(done.positions) & Counter(start)
    assert sum(kept.values()) == sum(
        1 for x, y in zip(start, done.positions, strict=True) if x == y
    )


def test_a_fleet_learns_between_stands_and_stores_them() -> None:
    stands = random_stands(11, (1,) * 15 + (2,))
    config = replace(
        learning_config(
            "consolidating", typical_cost=SPACE.typical_cost(), n_vehicles=4,
            objective=Objective(1.0),
        ),
        stands=stands,
    )  # fmt: skip
    vehicles = [(Vehicle(f"v{i}"), stands.positions[i]) for i in range(4)]
    fleet = Fleet.create(SPACE, vehicles, config)
    demand = hotspot_mixture(NET, centres=2, rng=np.random.default_rng(12))
    accepted = 0
    for z in demand.sample(np.random.default_rng(13), 700):
        outcome = fleet.observe(z)
        if outcome.consolidation is not None and outcome.consolidation.accepted:
            accepted += 1
            assert set(fleet.state.positions) <= set(stands.positions)
    assert accepted > 0
    at = fleet.stands()
    assert list(at.values()) == vehicle_stands(SPACE.cost_matrix, stands, fleet.state.positions)
    assert set(at.values()) <= set(stands.positions)
    # the config round-trips through JSON with the space's codec
    stored = json.loads(json.dumps(config.to_dict(SPACE.encode)))
    assert FleetConfig.from_dict(stored, SPACE.decode) == config
    with pytest.raises(InvalidInput, match="decoder"):
        FleetConfig.from_dict(stored)
    with pytest.raises(InvalidInput, match="encoder"):
        config.to_dict()
    with pytest.raises(InvalidInput, match="exceed the total capacity"):
        Fleet.create(SPACE, [(Vehicle(f"w{i}"), stands.positions[0]) for i in range(18)], config)


def test_a_config_without_stands_is_stored_as_before() -> None:
    config = learning_config(
        "consolidating", typical_cost=SPACE.typical_cost(), n_vehicles=3, objective=Objective(1.0)
    )
    stored = config.to_dict()
    assert "stands" not in stored
    again = FleetConfig.from_dict(json.loads(json.dumps(stored)))
    assert again.stands is None
    assert json.dumps(again.to_dict(), sort_keys=True) == json.dumps(stored, sort_keys=True)
