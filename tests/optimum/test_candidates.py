"""Candidate sites on the real DRT network: the vertex-optimality argument, checked."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from routing_svc.demand import DemandDistribution, uniform_by_length
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork, RoadSpace
from routing_svc.optimum import candidate_sites, solve_demand, solve_pmedian
from routing_svc.optimum.candidates import distinct_rows
from routing_svc.types import NetPosition
from tests.optimum.conftest import brute_force_pmedian


def test_candidates_are_the_atoms_and_every_edge_end(drt_network: CompiledNetwork) -> None:
    demand = uniform_by_length(drt_network, spacing=100.0)
    sites = candidate_sites(drt_network, demand)
    ends = {NetPosition(e, float(drt_network.length[e])) for e in range(drt_network.n_edges)}
    assert set(sites) == set(demand.positions) | ends
    assert len(sites) == len(set(sites))


def test_subsampling_is_deterministic_and_spread(drt_network: CompiledNetwork) -> None:
    demand = uniform_by_length(drt_network, spacing=100.0)
    every = candidate_sites(drt_network, demand)
    first = candidate_sites(drt_network, demand, max_sites=200)
    assert first == candidate_sites(drt_network, demand, max_sites=200)
    assert len(first) == 200 and set(first) <= set(every)
    atoms = set(demand.positions)
    assert any(s in atoms for s in first) and any(s not in atoms for s in first)
    with pytest.raises(InvalidInput):
        candidate_sites(drt_network, demand, max_sites=0)


def test_a_demand_of_fewer_atoms_than_the_limit_keeps_every_atom(
    drt_network: CompiledNetwork,
) -> None:
    net = drt_network
    edges = np.random.default_rng(11).choice(net.n_edges, size=5, replace=False)
    atoms = tuple(NetPosition(int(e), float(net.length[e]) / 3) for e in edges)
    demand = DemandDistribution.from_masses("five", atoms, np.array([1.0, 2.0, 3.0, 4.0, 5.0]))
    sites = candidate_sites(net, demand, max_sites=100)
    assert len(sites) == 100 and sites[:5] == list(atoms)
    ends = {NetPosition(e, float(net.length[e])) for e in range(net.n_edges)}
    assert set(sites[5:]) <= ends
    kept = sorted(s.edge for s in sites[5:])  # spread over the edge order
    assert kept[0] < net.n_edges // 10 and kept[-1] > net.n_edges - net.n_edges // 10
    # five vehicles, one on each atom: the p-median costs nothing
    best = solve_demand(RoadSpace(net), demand, 5, max_sites=100)
    assert best.objective == 0.0 and set(best.positions) == set(atoms)


def reverse_edge(network: CompiledNetwork, e: int) -> int | None:
    """The lowest-index edge joining the same two junctions the other way."""
    a, b = int(network.edge_from[e]), int(network.edge_to[e])
    back = np.flatnonzero((network.edge_from == b) & (network.edge_to == a))
    return int(back[0]) if back.size and a != b else None


def breakpoints(
    network: CompiledNetwork, demand: DemandDistribution[NetPosition], e: int, *, either_way: bool
) -> list[float]:
    """Offsets on ``e`` where the objective may jump: its ends, its atoms and (when
    vehicles may leave either way) the points facing the atoms of the reverse edge."""
    length = float(network.length[e])
    points = {0.0, length} | {p.offset for p in demand.positions if p.edge == e}
    r = reverse_edge(network, e) if either_way else None
    if r is not None:
        back = float(network.length[r])
        points |= {length * (1 - p.offset / back) for p in demand.positions if p.edge == r}
    return sorted(points)


@pytest.mark.parametrize("either_way", [False, True])
@pytest.mark.parametrize("cost", ["length", "time"])
def test_no_position_beats_both_ends_of_its_interval(
    drt_network: CompiledNetwork, either_way: bool, cost: str
) -> None:
    """Hakimi's argument, checked: between consecutive breakpoints ``a < s < b`` of an
    edge, for any other open sites (best costs ``m``), a site at ``s`` is never
    better than one at ``a`` or at ``b``; so atoms and edge ends suffice."""
    demand = uniform_by_length(drt_network, spacing=150.0)
    space = RoadSpace(drt_network, cost=cost, either_way=either_way)  # type: ignore[arg-type]
    rng = np.random.default_rng(1)
    probes, lows, highs = [], [], []
    for e in rng.choice(drt_network.n_edges, size=60, replace=False):
        points = breakpoints(drt_network, demand, int(e), either_way=either_way)
        for a, b in itertools.pairwise(points):
            for t in (1e-3, float(rng.uniform(0.0, 1.0)), 1 - 1e-3):
                probes.append(NetPosition(int(e), a + t * (b - a)))
                lows.append(NetPosition(int(e), a))
                highs.append(NetPosition(int(e), b))
    targets = list(demand.positions)
    at_probe, at_low, at_high = (space.cost_matrix(x, targets) for x in (probes, lows, highs))
    others = space.cost_matrix(
        [NetPosition(int(e), 0.0) for e in rng.choice(drt_network.n_edges, size=8)], targets
    )
    w = demand.weights
    for m in [np.full(len(targets), np.inf), others[:2].min(axis=0), others[2:].min(axis=0)]:
        value = np.minimum(at_probe, m) @ w
        best_end = np.minimum(np.minimum(at_low, m) @ w, np.minimum(at_high, m) @ w)
        assert np.all(best_end <= value * (1 + 1e-12) + 1e-9)


def test_facing_points_are_equivalent_to_the_atoms_they_face(
    drt_network: CompiledNetwork,
) -> None:
    demand = uniform_by_length(drt_network, spacing=150.0)
    space = RoadSpace(drt_network)
    pairs = []
    for atom in demand.positions[:400]:
        r = reverse_edge(drt_network, atom.edge)
        if r is not None:
            along = atom.offset / float(drt_network.length[atom.edge])
            facing = float(drt_network.length[r]) * (1 - along)
            pairs.append((atom, NetPosition(r, facing)))
    assert len(pairs) > 50
    targets = list(demand.positions)
    from_atoms = space.cost_matrix([a for a, _ in pairs], targets)
    from_facing = space.cost_matrix([f for _, f in pairs], targets)
    np.testing.assert_allclose(from_atoms, from_facing, rtol=0, atol=1e-6)


def test_exact_pmedian_on_the_drt_network_equals_brute_force(
    drt_network: CompiledNetwork,
) -> None:
    demand = uniform_by_length(drt_network, spacing=200.0)
    sites = candidate_sites(drt_network, demand, max_sites=45)
    costs = RoadSpace(drt_network).cost_matrix(sites, list(demand.positions))
    best = brute_force_pmedian(costs, demand.weights, 3)
    solution = solve_pmedian(costs, demand.weights, 3, method="milp", reduce=False)
    assert solution.proven_optimal
    assert solution.objective == pytest.approx(best, rel=1e-9)
    assert solve_pmedian(costs, demand.weights, 3).objective == pytest.approx(best, rel=1e-9)


def test_distinct_rows_keeps_the_first_of_equal_rows() -> None:
    costs = np.array([[1.0, 2.0], [0.0, 5.0], [1.0, 2.0], [0.0, 5.0], [3.0, 3.0]])
    assert distinct_rows(costs).tolist() == [0, 1, 4]


def test_distinct_rows_are_numpys_unique_rows() -> None:
    rng = np.random.default_rng(3)
    for _ in range(200):
        costs = rng.integers(0, 3, size=(int(rng.integers(1, 40)), int(rng.integers(1, 6))))
        signed = costs.astype(float) * rng.choice([-1.0, 1.0], size=costs.shape)  # -0.0 too
        _, first = np.unique(signed, axis=0, return_index=True)
        assert distinct_rows(signed).tolist() == sorted(first.tolist())
