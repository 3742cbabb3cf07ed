"""``solve_demand``: candidate sites -> cost matrix -> p-median, against brute force."""

from __future__ import annotations

import numpy as np
import pytest

from routing_svc.demand import DemandDistribution, uniform_by_length
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork, RoadSpace
from routing_svc.optimum import MAX_SITES, candidate_sites, expected_cost, solve_demand
from routing_svc.sa import EuclideanPlane
from routing_svc.types import PlanePosition
from tests.optimum.conftest import PlaneCosts, brute_force_pmedian


def test_default_sites_are_the_networks_candidates_up_to_max_sites(
    drt_network: CompiledNetwork,
) -> None:
    demand = uniform_by_length(drt_network, spacing=50.0)
    space = RoadSpace(drt_network)
    every = candidate_sites(drt_network, demand)
    assert len(every) > MAX_SITES
    best = solve_demand(space, demand, 4, method="heuristic")
    assert best.sites == candidate_sites(drt_network, demand, max_sites=MAX_SITES)
    assert best.matrix.shape == (MAX_SITES, len(demand.positions))
    assert len(best.positions) == 4 and set(best.positions) <= set(best.sites)
    exact = expected_cost(space, best.positions, np.ones(4), demand)
    assert best.objective == pytest.approx(exact, rel=1e-9)


@pytest.mark.parametrize("power", [1.0, 2.0])
def test_the_optimum_over_the_sites_is_the_brute_force_one(
    drt_network: CompiledNetwork, power: float
) -> None:
    demand = uniform_by_length(drt_network, spacing=200.0)
    space = RoadSpace(drt_network)
    best = solve_demand(space, demand, 3, max_sites=30, power=power, method="milp")
    sites = candidate_sites(drt_network, demand, max_sites=30)
    costs = space.cost_matrix(sites, list(demand.positions)) ** power
    assert best.sites == sites
    assert best.solution.proven_optimal
    assert best.objective == pytest.approx(brute_force_pmedian(costs, demand.weights, 3), rel=1e-9)
    exact = expected_cost(space, best.positions, np.ones(3), demand, power=power)
    assert best.objective == pytest.approx(exact, rel=1e-9)


def test_distinct_sites_give_the_same_optimum_with_fewer_rows(
    drt_network: CompiledNetwork,
) -> None:
    demand = uniform_by_length(drt_network, spacing=200.0)
    space = RoadSpace(drt_network)
    ends = candidate_sites(drt_network, demand)[-120:]  # edge ends: some share their junction
    every = solve_demand(space, demand, 3, sites=ends, method="milp")
    distinct = solve_demand(space, demand, 3, sites=ends, distinct=True, method="milp")
    assert len(distinct.sites) < len(every.sites) and set(distinct.sites) <= set(every.sites)
    assert len({tuple(row) for row in distinct.matrix.tolist()}) == len(distinct.sites)
    kept = [every.sites.index(site) for site in distinct.sites]
    assert kept == sorted(kept) and np.array_equal(distinct.matrix, every.matrix[kept])
    assert every.solution.proven_optimal and distinct.solution.proven_optimal
    assert distinct.objective == pytest.approx(every.objective, rel=1e-9)


def test_given_sites_on_the_plane() -> None:
    rng = np.random.default_rng(7)
    points = [PlanePosition(float(x), float(y)) for x, y in rng.uniform(0, 10, size=(12, 2))]
    demand = DemandDistribution.from_masses("points", points, rng.uniform(1, 2, size=12))
    sites = points[:9]
    best = solve_demand(EuclideanPlane(side=10.0), demand, 3, sites=sites, method="milp")
    costs = PlaneCosts().cost_matrix(sites, points)
    assert best.sites == sites
    assert best.objective == pytest.approx(brute_force_pmedian(costs, demand.weights, 3), rel=1e-9)
    with pytest.raises(TypeError, match="road network"):
        solve_demand(EuclideanPlane(side=10.0), demand, 3)


def test_more_vehicles_than_sites_is_invalid(drt_network: CompiledNetwork) -> None:
    demand = uniform_by_length(drt_network, spacing=200.0)
    space = RoadSpace(drt_network)
    with pytest.raises(InvalidInput, match="a fleet of 6 vehicles exceeds the 5 candidate sites"):
        solve_demand(space, demand, 6, max_sites=5)
    with pytest.raises(InvalidInput, match="exceeds the 1 distinct candidate sites"):
        solve_demand(space, demand, 2, sites=[demand.positions[0]] * 3, distinct=True)
