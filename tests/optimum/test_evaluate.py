"""Exact expected cost against explicit loops over vehicles and atoms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from routing_svc.demand import DemandDistribution, gaussian_mixture, uniform_by_length
from routing_svc.errors import InvalidInput, Unreachable
from routing_svc.network import CompiledNetwork, RoadSpace
from routing_svc.optimum import expected_cost, gap
from routing_svc.types import FloatArray, NetPosition, PlanePosition
from tests.optimum.conftest import PlaneCosts, WindyCosts


def loop_cost(
    pair_cost: object,
    positions: list[PlanePosition],
    speeds: list[float],
    demand: DemandDistribution[PlanePosition],
    power: float,
) -> float:
    total = 0.0
    for z, w in zip(demand.positions, demand.weights, strict=True):
        times = [pair_cost(p, z) / v for p, v in zip(positions, speeds, strict=True)]  # type: ignore[operator]
        total += float(w) * min(times) ** power
    return total


def euclid(a: PlanePosition, b: PlanePosition) -> float:
    return math.hypot(a.x - b.x, a.y - b.y)


@pytest.fixture
def demand() -> DemandDistribution[PlanePosition]:
    return gaussian_mixture(
        (0.0, 0.0, 10.0, 10.0), centres=[(2.0, 3.0), (7.0, 7.5)], spread=1.5, cells=12
    )


@pytest.mark.parametrize("power", [1.0, 2.0, 1.5])
def test_plane_cost_matches_a_loop(demand: DemandDistribution[PlanePosition], power: float) -> None:
    rng = np.random.default_rng(1)
    positions = [PlanePosition(*map(float, rng.uniform(0, 10, 2))) for _ in range(4)]
    speeds = [1.0, 2.0, 0.5, 1.5]
    value = expected_cost(PlaneCosts(), positions, speeds, demand, power=power)
    assert value == pytest.approx(loop_cost(euclid, positions, speeds, demand, power), rel=1e-12)


def test_directed_costs_run_from_vehicle_to_target(
    demand: DemandDistribution[PlanePosition],
) -> None:
    rng = np.random.default_rng(2)
    positions = [PlanePosition(*map(float, rng.uniform(0, 10, 2))) for _ in range(3)]
    speeds = [1.0, 1.0, 1.0]
    value = expected_cost(WindyCosts(), positions, speeds, demand)
    forward = loop_cost(WindyCosts.pair, positions, speeds, demand, 1.0)
    backward = loop_cost(lambda a, b: WindyCosts.pair(b, a), positions, speeds, demand, 1.0)
    assert value == pytest.approx(forward, rel=1e-12)
    assert abs(forward - backward) > 1e-3 * forward


def test_a_vehicle_on_every_atom_costs_nothing(demand: DemandDistribution[PlanePosition]) -> None:
    positions = list(demand.positions)
    assert expected_cost(PlaneCosts(), positions, np.ones(len(positions)), demand) == 0.0


def test_network_cost_matches_single_pair_searches(drt_network: CompiledNetwork) -> None:
    """The cost matrix (scipy Dijkstra) against the space's own one-pair search."""
    space = RoadSpace(drt_network)
    atoms = uniform_by_length(drt_network, spacing=400.0)
    rng = np.random.default_rng(3)
    edges = rng.choice(drt_network.n_edges, size=3, replace=False)
    positions = [NetPosition(int(e), float(drt_network.length[e]) / 3) for e in edges]
    speeds = [1.0, 1.3, 0.8]
    expected = math.fsum(
        float(w) * min(space.path_cost(p, z) / v for p, v in zip(positions, speeds, strict=True))
        for z, w in zip(atoms.positions, atoms.weights, strict=True)
    )
    assert expected_cost(space, positions, speeds, atoms) == pytest.approx(expected, rel=1e-9)


class _Unreachable:
    def cost_matrix(self, sources: list[PlanePosition], targets: list[PlanePosition]) -> FloatArray:
        out = np.ones((len(sources), len(targets)))
        out[:, -1] = np.inf
        return out


class _WrongShape:
    def cost_matrix(self, sources: list[PlanePosition], targets: list[PlanePosition]) -> FloatArray:
        return np.ones((len(targets), len(sources) + 1))


def test_errors(demand: DemandDistribution[PlanePosition]) -> None:
    one = [PlanePosition(1.0, 1.0)]
    with pytest.raises(Unreachable, match="cannot be reached"):
        expected_cost(_Unreachable(), one, [1.0], demand)
    with pytest.raises(InvalidInput, match="shape"):
        expected_cost(_WrongShape(), one, [1.0], demand)
    with pytest.raises(InvalidInput, match="at least one vehicle"):
        expected_cost(PlaneCosts(), [], [], demand)
    with pytest.raises(InvalidInput, match="speeds"):
        expected_cost(PlaneCosts(), one, [0.0], demand)
    with pytest.raises(InvalidInput, match="speeds"):
        expected_cost(PlaneCosts(), one, [1.0, 2.0], demand)
    with pytest.raises(InvalidInput, match="power"):
        expected_cost(PlaneCosts(), one, [1.0], demand, power=float("nan"))


def test_gap() -> None:
    assert gap(110.0, 100.0) == pytest.approx(0.1)
    assert gap(100.0, 100.0) == 0.0
    assert gap(0.0, 0.0) == 0.0
    assert gap(90.0, 100.0) == pytest.approx(-0.1)
    assert gap(1.0, 0.0) is None  # no finite relative gap
    for value, optimum in [(-1.0, 1.0), (1.0, math.inf), (math.nan, 1.0), (1.0, -1.0)]:
        with pytest.raises(InvalidInput):
            gap(value, optimum)
