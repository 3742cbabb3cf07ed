"""The optimum over stands against enumeration of every placement within the capacities."""

from __future__ import annotations

import itertools
import math
from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

from routing_svc.demand import DemandDistribution
from routing_svc.demand.network import hotspot_mixture
from routing_svc.errors import InvalidInput
from routing_svc.network import RoadSpace, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.optimum import expected_cost, solve_demand
from routing_svc.optimum.pmedian import PMedianSolution, objective
from routing_svc.optimum.stands import polished, solve_stands
from routing_svc.sa.stands import StandSet
from routing_svc.types import NetPosition

NET = load_network(resolve_network("drt"))
SPACE = RoadSpace(NET, cost="length")


def random_stands(seed: int, capacities: tuple[int, ...]) -> StandSet[NetPosition]:
    rng = np.random.default_rng(seed)
    edges = rng.choice(NET.n_edges, size=len(capacities), replace=False)
    positions = [
        NetPosition(int(e), float(rng.uniform(0.0, float(NET.length[int(e)])))) for e in edges
    ]
    return StandSet(tuple(positions), capacities)


def small_demand(seed: int, atoms: int) -> DemandDistribution[NetPosition]:
    """A hotspot demand on DRT, kept to its ``atoms`` heaviest atoms (renormalised)."""
    full = hotspot_mixture(NET, centres=3, rng=np.random.default_rng(50 + seed))
    keep = np.argsort(-np.asarray(full.weights), kind="stable")[:atoms]
    weights = np.asarray(full.weights)[keep]
    return DemandDistribution.from_masses(
        "small", tuple(full.positions[int(i)] for i in keep), weights / weights.sum()
    )


def brute_force(
    stands: StandSet[NetPosition], demand: DemandDistribution[NetPosition], p: int, power: float
) -> float:
    """The least expected cost over every multiset of ``p`` stands within the capacities."""
    best = math.inf
    for rows in itertools.combinations_with_replacement(range(len(stands.positions)), p):
        if any(k > stands.capacities[i] for i, k in Counter(rows).items()):
            continue
        at = [stands.positions[i] for i in rows]
        best = min(best, expected_cost(SPACE, at, np.ones(p), demand, power=power))
    return best


@pytest.mark.parametrize(
    ("seed", "capacities", "p", "power"),
    [
        (0, (1, 1, 1, 1, 1, 1, 1), 3, 1.0),
        (1, (1, 1, 1, 1, 1, 1, 1, 1), 4, 2.0),
        (2, (3, 1, 2, 1, 1), 4, 1.0),
        (3, (2, 1, 3), 5, 1.0),  # more vehicles than stands: stands hold several
        (4, (1, 2), 3, 1.0),  # every place taken
    ],
)
def test_the_stand_optimum_equals_enumeration(
    seed: int, capacities: tuple[int, ...], p: int, power: float
) -> None:
    stands = random_stands(seed, capacities)
    demand = small_demand(seed, 25)
    found = solve_stands(SPACE, demand, p, stands, power=power)
    assert len(found.positions) == p
    assert set(found.positions) <= set(stands.positions)
    counts = Counter(found.positions)
    assert all(counts[x] <= c for x, c in zip(stands.positions, stands.capacities, strict=True))
    assert len(counts) == min(p, len(stands.positions))
    value = expected_cost(SPACE, found.positions, np.ones(p), demand, power=power)
    best = brute_force(stands, demand, p, power)
    assert value == pytest.approx(best, rel=1e-9)
    assert found.objective == pytest.approx(best, rel=1e-9)
    assert [stands.positions[i] for i in found.slots.tolist()] == found.positions


def test_the_stand_optimum_is_no_better_than_the_free_one() -> None:
    demand = small_demand(5, 40)
    stands = random_stands(5, (1,) * 12)
    free = solve_demand(SPACE, demand, 3)
    assert solve_stands(SPACE, demand, 3, stands).objective >= free.objective * (1 - 1e-12)


def test_more_vehicles_than_the_stands_hold() -> None:
    stands = random_stands(6, (2, 1))
    with pytest.raises(InvalidInput, match="exceed the total capacity 3"):
        solve_stands(SPACE, small_demand(6, 10), 4, stands)


def test_an_unproven_answer_is_polished_and_a_proven_one_kept() -> None:
    rng = np.random.default_rng(7)
    matrix, weights = rng.exponential(10.0, size=(12, 30)), rng.random(30)
    poor = max(
        itertools.combinations(range(12), 3), key=lambda s: objective(matrix, weights, list(s))
    )
    unproven = PMedianSolution(
        poor, objective(matrix, weights, list(poor)), "milp", False, 1.0, 0.5
    )
    better = polished(unproven, matrix, weights)
    assert better.objective < unproven.objective
    assert better.objective == objective(matrix, weights, list(better.sites))
    assert len(set(better.sites)) == 3
    assert (better.method, better.proven_optimal, better.lower_bound) == ("milp", False, 0.5)
    proven = replace(unproven, proven_optimal=True)
    assert polished(proven, matrix, weights) is proven
