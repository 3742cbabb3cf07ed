"""Leaving a reference position either way on two-way streets, against networkx.

The reference builds the twin of a position from sumolib's own junction ids
(the edge that joins the same two junctions the other way) and takes the
smaller networkx cost of the position and its twin.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
import sumolib

from routing_svc.network import RoadSpace
from routing_svc.network import space as space_module
from routing_svc.sa.requirements import build_requirement
from routing_svc.types import NetPosition
from tests.network.conftest import NetCase


def sumolib_twins(case: NetCase) -> dict[str, str]:
    net = sumolib.net.readNet(str(case.path), withInternal=False)
    by_ends: dict[tuple[str, str], list[str]] = {}
    for edge in net.getEdges():
        by_ends.setdefault((edge.getFromNode().getID(), edge.getToNode().getID()), []).append(
            edge.getID()
        )
    kept = set(case.network.edge_ids)
    twins = {}
    for edge in net.getEdges():
        a, b = edge.getFromNode().getID(), edge.getToNode().getID()
        back = [e for e in by_ends.get((b, a), []) if e in kept]
        if edge.getID() in kept and back and a != b:
            twins[edge.getID()] = min(back, key=case.network.edge_index.__getitem__)
    return twins


def reference_cost(
    case: NetCase, twins: dict[str, str], vehicle: NetPosition, target: NetPosition,
    start: dict[str, float], costs: dict[str, float],
) -> float:  # fmt: skip
    ref = case.reference
    e, s = case.ids(vehicle)
    best = ref.vehicle_cost((e, s), case.ids(target), costs, start)
    if e in twins:
        r = twins[e]
        s_r = ref.length(r) * (1.0 - s / ref.length(e))
        best = min(best, ref.vehicle_cost((r, s_r), case.ids(target), costs, start))
    return best


def reference_costs(
    case: NetCase, twins: dict[str, str], sources: list[NetPosition], target: NetPosition
) -> npt.NDArray[np.float64]:
    """The networkx cost from each source to ``target``, leaving either way on length costs."""
    ref = case.reference
    costs = ref.edge_costs(kind="length")
    start = ref.start_costs(case.ids(target), costs, ref.weighted(costs))
    return np.array([reference_cost(case, twins, s, target, start, costs) for s in sources])


def test_either_way_costs_match_networkx(case: NetCase) -> None:
    space = RoadSpace(case.network)
    twins = sumolib_twins(case)
    rng = np.random.default_rng(17)
    req, _ = build_requirement(["a"] * 6, None)
    for _ in range(300):
        target = case.random_positions(rng, 1)[0]
        vehicles = case.random_positions(rng, 6)
        # a vehicle on the target's reverse edge, just across the street
        twin_id = twins.get(case.network.edge_ids[target.edge])
        if twin_id is not None:
            r = case.network.edge_index[twin_id]
            vehicles[0] = NetPosition(r, float(rng.uniform(0, case.network.length[r])))
        expected = reference_costs(case, twins, vehicles, target)
        found = space.assign(target, vehicles, np.ones(6), req)
        best = int(min(range(6), key=lambda i: (expected[i], i)))
        assert found.served_by == (best,)
        np.testing.assert_allclose(found.completion_time, expected[best], rtol=1e-9)
        np.testing.assert_allclose(space.cost_matrix(vehicles, [target])[:, 0], expected, rtol=1e-9)


def test_either_way_matrix_in_blocks_matches_networkx(
    case: NetCase, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Blocks of two twin rows at a time, as a large network's matrix is filled."""
    targets_count = 12
    monkeypatch.setattr(space_module, "_TWIN_BLOCK_CELLS", 2 * targets_count)
    space = RoadSpace(case.network)
    twins = sumolib_twins(case)
    rng = np.random.default_rng(29)
    sources = case.random_positions(rng, 25)
    targets = case.random_positions(rng, targets_count)
    assert sum(case.network.edge_ids[s.edge] in twins for s in sources) > 2  # several blocks
    expected = np.column_stack([reference_costs(case, twins, sources, t) for t in targets])
    np.testing.assert_allclose(space.cost_matrix(sources, targets), expected, rtol=1e-9)


def test_either_way_never_costs_more_than_forward_only(case: NetCase) -> None:
    both = RoadSpace(case.network)
    forward = RoadSpace(case.network, either_way=False)
    rng = np.random.default_rng(5)
    sources = case.random_positions(rng, 40)
    targets = case.random_positions(rng, 40)
    a = both.cost_matrix(sources, targets)
    b = forward.cost_matrix(sources, targets)
    assert (a <= b + 1e-9).all()
    assert (a < b - 1.0).any()  # some trips really are shorter by turning around


def test_moving_toward_a_target_behind_turns_the_vehicle_around(case: NetCase) -> None:
    space = RoadSpace(case.network)
    twins = sumolib_twins(case)
    edge_id = next(iter(sorted(twins)))
    e = case.network.edge_index[edge_id]
    length = float(case.network.length[e])
    vehicle = NetPosition(e, 0.8 * length)
    target = NetPosition(e, 0.2 * length)  # behind on the same lane
    req, _ = build_requirement(["a"], None)
    found = space.assign(target, [vehicle], np.ones(1), req)
    moved = space.advance(vehicle, target, found.route, 1.0)
    assert case.network.edge_ids[moved.edge] == twins[edge_id]
    assert space.cost_matrix([moved], [target])[0, 0] <= found.mover_cost - 1.0 + 1e-9
