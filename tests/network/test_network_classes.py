"""End-state classes: the compressed graph the nearest-vehicle search runs on.

Edges with the same successor set share one class; the search runs its
Dijkstra over classes. These tests check the classes themselves and that the
search over them stays exact against networkx on a grid (where the classes
collapse to about one per junction) and on nets with turn restrictions.
"""

from __future__ import annotations

import re
from collections import defaultdict

import numpy as np
import pytest

from routing_svc.errors import InvalidInput
from routing_svc.network import RoadSpace, layout
from routing_svc.network.costs import position_columns
from routing_svc.network.layout import EndStateClasses, end_state_classes
from routing_svc.network.search import ARC_DTYPE, fleet_columns, search_arcs
from routing_svc.sa.space import Requirement
from routing_svc.types import NetPosition
from tests.helpers import run_queries
from tests.network.conftest import NetCase


def successor_sets(case: NetCase) -> list[frozenset[int]]:
    net = case.network
    return [
        frozenset(net.fwd_indices[net.fwd_indptr[e] : net.fwd_indptr[e + 1]].tolist())
        for e in range(net.n_edges)
    ]


def check_classes(case: NetCase, classes: EndStateClasses) -> None:
    """Classes are exactly the successor sets, and the arcs are the reverse class graph."""
    net = case.network
    members: dict[int, set[frozenset[int]]] = defaultdict(set)
    for e, successors in enumerate(successor_sets(case)):
        members[int(classes.edge_class[e])].add(successors)
    assert sorted(members) == list(range(classes.n_classes))
    assert all(len(sets) == 1 for sets in members.values())
    assert len({next(iter(sets)) for sets in members.values()}) == classes.n_classes
    first_edge = [int(np.flatnonzero(classes.edge_class == c)[0]) for c in range(classes.n_classes)]
    assert first_edge == sorted(first_edge)

    expected = sorted(
        {
            (int(classes.edge_class[y]), y, int(classes.edge_class[p]))
            for y in range(net.n_edges)
            for p in net.rev_indices[net.rev_indptr[y] : net.rev_indptr[y + 1]].tolist()
        }
    )
    owners = np.repeat(np.arange(classes.n_classes), np.diff(classes.arc_indptr))
    found = list(
        zip(owners.tolist(), classes.arc_edge.tolist(), classes.arc_class.tolist(), strict=True)
    )
    assert found == expected


@pytest.mark.parametrize("name", ["drt", "oneway", "grid", "restricted"])
def test_classes_are_successor_sets(request: pytest.FixtureRequest, name: str) -> None:
    case: NetCase = request.getfixturevalue(f"{name}_case")
    classes = case.network.end_classes
    check_classes(case, classes)
    for array in (classes.edge_class, classes.arc_indptr, classes.arc_edge, classes.arc_class):
        assert array.dtype == np.int32
        assert not array.flags.writeable
    assert case.network.end_classes is classes  # computed once per network


def test_grid_collapses_to_one_class_per_junction(grid_case: NetCase) -> None:
    net = grid_case.network
    classes = net.end_classes
    ends = defaultdict(set)
    for e in range(net.n_edges):
        ends[int(net.edge_to[e])].add(int(classes.edge_class[e]))
    # every turn is allowed, so all edges into a junction share its end state, except at
    # the four corners, where netgenerate builds no U-turn
    split = [j for j, c in ends.items() if len(c) > 1]
    assert len(split) == 4
    assert all(len(ends[j]) == 2 and (net.edge_to == j).sum() == 2 for j in split)
    assert classes.n_classes == len(ends) + 4
    assert classes.n_classes < net.n_edges / 3
    assert classes.arc_edge.shape[0] < net.n_connections / 3


def test_turn_restrictions_split_classes(restricted_case: NetCase, grid_case: NetCase) -> None:
    net = restricted_case.network
    classes = net.end_classes
    ends = defaultdict(set)
    for e in range(net.n_edges):
        ends[int(net.edge_to[e])].add(int(classes.edge_class[e]))
    assert sum(len(c) > 1 for c in ends.values()) > 20
    assert classes.n_classes > grid_case.network.end_classes.n_classes


def test_hash_collisions_fall_back_to_exact_classes(
    case: NetCase, monkeypatch: pytest.MonkeyPatch
) -> None:
    net = case.network
    hashed = net.end_classes
    monkeypatch.setattr(layout, "_same_rows", lambda *args: False)
    exact = end_state_classes(net.fwd_indptr, net.fwd_indices, net.rev_indptr, net.rev_indices)
    for name in ("edge_class", "arc_indptr", "arc_edge", "arc_class"):
        np.testing.assert_array_equal(getattr(exact, name), getattr(hashed, name), err_msg=name)


def test_unsorted_successor_lists_give_the_same_classes(drt_case: NetCase) -> None:
    net = drt_case.network
    rng = np.random.default_rng(31)
    shuffled = net.fwd_indices.copy()
    for e in range(net.n_edges):
        rng.shuffle(shuffled[net.fwd_indptr[e] : net.fwd_indptr[e + 1]])
    assert (shuffled != net.fwd_indices).any()
    classes = end_state_classes(net.fwd_indptr, shuffled, net.rev_indptr, net.rev_indices)
    np.testing.assert_array_equal(classes.edge_class, net.end_classes.edge_class)
    np.testing.assert_array_equal(classes.arc_class, net.end_classes.arc_class)


@pytest.mark.parametrize("name", ["grid", "restricted", "drt"])
def test_search_over_classes_matches_networkx(request: pytest.FixtureRequest, name: str) -> None:
    case: NetCase = request.getfixturevalue(f"{name}_case")
    space = RoadSpace(case.network, either_way=False)
    rng = np.random.default_rng(32)
    costs = case.reference.edge_costs(kind="length")
    for n, counts, n_targets in ((40, [1], 400), (60, [2, 1, 3], 300), (3, [1], 300)):
        positions = case.random_positions(rng, n)
        groups = np.arange(n) % len(counts)
        run_queries(
            case,
            space,
            rng,
            n_targets=n_targets,
            positions=positions,
            speeds=rng.uniform(0.3, 3.0, n),
            requirement=Requirement(groups, np.array(counts)),
            costs=costs,
        )


def test_vehicles_on_edges_of_one_class(grid_case: NetCase) -> None:
    """Vehicles on different edges into one junction, behind and ahead of the target."""
    net = grid_case.network
    space = RoadSpace(net, either_way=False)
    classes = net.end_classes
    costs = grid_case.reference.edge_costs(kind="length")
    rng = np.random.default_rng(33)
    for target in grid_case.random_positions(rng, 200):
        same = np.flatnonzero(classes.edge_class == classes.edge_class[target.edge]).tolist()
        positions = [NetPosition(e, float(rng.uniform(0.0, net.length[e]))) for e in same]
        positions.append(NetPosition(target.edge, float(rng.uniform(0.0, net.length[target.edge]))))
        n = len(positions)
        run_queries(
            grid_case,
            space,
            rng,
            n_targets=1,
            positions=positions,
            speeds=np.ones(n),
            requirement=Requirement(np.zeros(n, dtype=np.int64), np.array([min(n, 3)])),
            costs=costs,
        )


@pytest.mark.parametrize(
    "positions",
    [
        [],
        [NetPosition(3, 1.5), NetPosition(0, 0.0)],
        [(3, 1), (4, 2.5)],
        [(np.int64(3), 1.0)],
        [(3, np.float32(1.25))],
        [(True, 1.0), (2, 1.0)],
        [(3, "1.5")],
        [(2**70, 1.0)],
        [(0.5, 1.0)],
        [(1.0, 1.0)],
        [(3, 1.0, 2.0)],
        [(3,)],
        [(3, None)],
        [3],
        [(3, [1.0])],
    ],
)
def test_fleet_columns_match_position_columns(positions: list[object]) -> None:
    try:
        expected = position_columns(positions, what="vehicle")  # type: ignore[arg-type]
    except InvalidInput as error:
        with pytest.raises(InvalidInput, match=re.escape(str(error))):
            fleet_columns(positions)  # type: ignore[arg-type]
        return
    edges, offsets = fleet_columns(positions)  # type: ignore[arg-type]
    assert edges.dtype == np.int64 and offsets.dtype == np.float64
    np.testing.assert_array_equal(edges, expected[0])
    np.testing.assert_array_equal(offsets, expected[1])


def test_search_arcs_follow_the_space_costs(drt_case: NetCase) -> None:
    net = drt_case.network
    classes = net.end_classes
    space = RoadSpace(net, cost="time", either_way=False)
    arcs = search_arcs(classes, space.edge_costs)
    assert search_arcs(classes, space.edge_costs) is arcs  # built once per cost set
    assert arcs.dtype == ARC_DTYPE and ARC_DTYPE.itemsize == 16
    assert not arcs.flags.writeable
    np.testing.assert_array_equal(arcs["cost"], space.edge_costs.cost[classes.arc_edge])
    np.testing.assert_array_equal(arcs["cls"], classes.arc_class)
    np.testing.assert_array_equal(arcs["edge"], classes.arc_edge)
    edge = int(classes.arc_edge[0])
    slower = space.with_travel_times({net.edge_ids[edge]: 999.0})
    changed = search_arcs(classes, slower.edge_costs)
    assert (changed["cost"][classes.arc_edge == edge] == 999.0).all()
    assert (arcs["cost"][classes.arc_edge == edge] != 999.0).all()
