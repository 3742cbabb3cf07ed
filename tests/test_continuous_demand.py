"""``bench/continuous.py``: targets anywhere along the road, and the fine model that prices
them, checked against its definition and against a dense sum of the exact costs; and
``bench/learning.py --anywhere`` and ``bench/heterogeneous.py --anywhere`` measure
fleets on that model."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.demand.network import hotspot_mixture
from routing_svc.network import RoadSpace, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.optimum import expected_cost, solve_demand
from routing_svc.types import NetPosition
from tests.helpers import bench_report

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # after every other module
from continuous import (
    CONTINUOUS_PARTS,
    ContinuousDemand,
    continuous,
    piece_bounds,
    piece_starts,
    priced_along,
)


def _town() -> tuple[RoadSpace, DemandDistribution[NetPosition]]:
    network = load_network(resolve_network("grid"))
    return RoadSpace(network), hotspot_mixture(network, rng=np.random.default_rng(3))


def test_targets_fall_within_the_piece_of_an_atom_and_never_on_one() -> None:
    space, coarse = _town()
    network = space.network
    demand = continuous(network, coarse)
    atoms = set(demand.coarse.positions)
    drawn = demand.sample(np.random.default_rng(7), 4000)
    assert demand.sample(np.random.default_rng(7), 1000) == drawn[:1000]  # a prefix
    assert not atoms & set(drawn)
    assert len(set(drawn)) == len(drawn)
    by_edge: dict[int, list[float]] = {}
    for z in demand.coarse.positions:
        by_edge.setdefault(z.edge, []).append(z.offset)
    for z in drawn:
        length = float(network.length[z.edge])
        piece = length / max(1, math.ceil(length / 20.0))
        nearest = min(by_edge[z.edge], key=lambda x: abs(x - z.offset))
        assert abs(z.offset - nearest) <= piece / 2 + 1e-9
        assert 0.0 <= z.offset <= length


def test_targets_fall_on_the_edges_as_the_demand_weighs_them() -> None:
    space, coarse = _town()
    demand = continuous(space.network, coarse)
    drawn = demand.sample(np.random.default_rng(11), 40_000)
    weight: dict[int, float] = {}
    for z, w in zip(coarse.positions, coarse.weights.tolist(), strict=True):
        weight[z.edge] = weight.get(z.edge, 0.0) + w
    counts: dict[int, int] = {}
    for z in drawn:
        counts[z.edge] = counts.get(z.edge, 0) + 1
    assert set(counts) <= set(weight)
    apart = sum(abs(counts.get(e, 0) / len(drawn) - w) for e, w in weight.items()) / 2
    assert apart < 0.03


def test_the_fine_model_splits_each_atom_evenly_along_its_piece() -> None:
    space, coarse = _town()
    demand = continuous(space.network, coarse)
    k = CONTINUOUS_PARTS
    assert len(demand.positions) == k * len(demand.coarse.positions)
    assert math.isclose(float(demand.weights.sum()), 1.0, abs_tol=1e-12)
    for j, z in enumerate(demand.coarse.positions):
        parts = demand.positions[k * j : k * (j + 1)]
        assert {p.edge for p in parts} == {z.edge}
        assert math.isclose(sum(p.offset for p in parts) / k, z.offset, abs_tol=1e-9)
        steps = np.diff([p.offset for p in parts])
        assert np.allclose(steps, demand.pieces[j] / k)
        assert np.allclose(demand.weights[k * j : k * (j + 1)], demand.coarse.weights[j] / k)


def _dense(
    space: RoadSpace,
    fleet: list[NetPosition],
    coarse: DemandDistribution[NetPosition],
    demand: ContinuousDemand,
    points_a_piece: int = 400,
) -> float:
    """The expected cost as a dense midpoint sum of the exact costs along each piece."""
    start, end = piece_bounds(demand)
    points, weights = [], []
    for j, z in enumerate(coarse.positions):
        parts = (np.arange(points_a_piece) + 0.5) / points_a_piece
        for x in start[j] + parts * (end[j] - start[j]):
            points.append(NetPosition(z.edge, float(x)))
            weights.append(coarse.weights[j] / points_a_piece)
    total = float(np.asarray(weights) @ space.cost_matrix(fleet, points).min(axis=0))
    return total / float(coarse.weights.sum())


def test_the_fine_model_prices_a_fleet_as_a_dense_sum_along_the_pieces() -> None:
    """Three vehicles at the heaviest atoms of a one-way network: the expected cost on the
    fine model against 200 points a piece (on a one-way street the half of a piece behind
    a vehicle costs a loop round the block, which the coarse atoms do not see)."""
    network = load_network(resolve_network("oneway"))
    space = RoadSpace(network)
    coarse = hotspot_mixture(network, rng=np.random.default_rng(3))
    demand = continuous(network, coarse)
    fleet = [coarse.positions[int(i)] for i in np.argsort(coarse.weights)[::-1][:3]]
    dense = _dense(space, fleet, coarse, demand, points_a_piece=200)
    fine = expected_cost(space, fleet, np.ones(3), demand)
    at_atoms = expected_cost(space, fleet, np.ones(3), coarse)
    assert math.isclose(fine, dense, rel_tol=1.5e-3)
    assert abs(fine - dense) < abs(at_atoms - dense) / 3


def test_priced_along_is_the_dense_sum_with_vehicles_inside_pieces() -> None:
    """Twenty vehicles at drawn targets (inside pieces, on one-way and two-way streets,
    the strictly directed model and the twin rule): the closed form against 400 points a
    piece, and the fine model, which charges a loop to the part behind each vehicle,
    further off."""
    for name, either_way in (("oneway", True), ("grid", True), ("grid", False)):
        network = load_network(resolve_network(name))
        space = RoadSpace(network, either_way=either_way)
        coarse = hotspot_mixture(network, rng=np.random.default_rng(3))
        demand = continuous(network, coarse)
        fleet = demand.sample(np.random.default_rng(9), 20)
        dense = _dense(space, fleet, coarse, demand)
        exact = priced_along(space, fleet, demand)
        fine = expected_cost(space, fleet, np.ones(20), demand)
        assert math.isclose(exact, dense, rel_tol=1e-4), (name, either_way)
        assert abs(exact - dense) < abs(fine - dense) / 10, (name, either_way)


def test_the_starts_of_the_pieces_are_priced_exactly_by_the_coarse_atoms() -> None:
    """A p-median of the coarse atoms over the starts of their pieces costs, by its own
    objective, what the closed form integrates along the pieces."""
    network = load_network(resolve_network("oneway"))
    space = RoadSpace(network)
    coarse = hotspot_mixture(network, rng=np.random.default_rng(3))
    demand = continuous(network, coarse)
    starts = piece_starts(demand, list(coarse.positions))
    assert len(starts) == len(coarse.positions)
    pairs = zip(starts, coarse.positions, strict=True)
    assert all(a.edge == z.edge and a.offset <= z.offset for a, z in pairs)
    best = solve_demand(space, coarse, 5, sites=starts)
    assert math.isclose(best.objective, priced_along(space, best.positions, demand), rel_tol=1e-9)


def test_learning_bench_measures_targets_anywhere(tmp_path: Path) -> None:
    report, _ = bench_report(
        "learning.py", tmp_path, "--nets", "grid", "--vehicles", "4", "--seeds", "0",
        "--rules", "consolidating", "--scenarios", "cold,warm", "--targets", "1000",
        "--jobs", "1", "--anywhere",
    )  # fmt: skip
    assert report["anywhere"] is True
    (record,) = report["records"]
    assert record["anywhere"] is True
    assert record["atoms"] % CONTINUOUS_PARTS == 0
    gaps = record["rules"]["consolidating"]
    assert set(gaps["cold"]["gaps"]) == {"300", "1000"}
    assert all(math.isfinite(g) for g in gaps["cold"]["gaps"].values())
    assert all(abs(g) <= 0.015 for g in gaps["warm"]["gaps"].values())


def test_typed_bench_prices_its_optimum_on_the_same_fine_model(tmp_path: Path) -> None:
    """The typed optimum is solved on the fine model's matrix and priced by objective (11)
    on the fine model: the two agree; the same targets anywhere through a live service
    learn as in process."""
    report, _ = bench_report(
        "heterogeneous.py", tmp_path, "--nets", "drt", "--vehicles", "4", "--seeds", "0",
        "--targets", "300", "--jobs", "1", "--mix", "thirds", "--rest", "--anywhere",
    )  # fmt: skip
    assert report["anywhere"] is True
    (record,) = report["records"]
    assert abs(record["gap_at_optimum"]) < 1e-9
    assert report["rest"]["gaps"] == report["rest"]["in_process"]
