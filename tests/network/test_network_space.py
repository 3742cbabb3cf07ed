"""RoadSpace: path costs, cost matrices, walking, perturbation, encoding, coordinates."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from routing_svc.errors import InvalidInput, UnknownEdge
from routing_svc.network import RoadSpace
from routing_svc.network.costs import (
    _ROWS_PER_THREAD,
    DistanceRows,
    EdgeCosts,
    _least_over_predecessors,
)
from routing_svc.sa.space import Requirement
from routing_svc.types import NetPosition
from tests.network.conftest import NetCase

RTOL = 1e-9
ONE = Requirement(np.zeros(1, dtype=np.int64), np.ones(1, dtype=np.int64))


def test_path_cost_matches_networkx(case: NetCase, space: RoadSpace) -> None:
    """2,000 random pairs: 100 targets, 20 sources each."""
    rng = np.random.default_rng(21)
    ref = case.reference
    costs = ref.edge_costs(kind="length")
    weighted = ref.weighted(costs)
    for target in case.random_positions(rng, 100):
        start = ref.start_costs(case.ids(target), costs, weighted)
        sources = case.random_positions(rng, 18)
        sources += [NetPosition(target.edge, 0.0), NetPosition(target.edge, target.offset)]
        for source in sources:
            expected = ref.vehicle_cost(case.ids(source), case.ids(target), costs, start)
            np.testing.assert_allclose(
                space.path_cost(source, target), expected, rtol=RTOL, atol=1e-9
            )


def test_cost_matrix_matches_path_costs(case: NetCase, space: RoadSpace) -> None:
    rng = np.random.default_rng(22)
    sources = case.random_positions(rng, 40)
    targets = [*case.random_positions(rng, 30), sources[0], NetPosition(sources[1].edge, 0.0)]
    matrix = space.cost_matrix(sources, targets)
    assert matrix.shape == (40, 32)
    expected = np.array([[space.path_cost(s, t) for t in targets] for s in sources])
    np.testing.assert_allclose(matrix, expected, rtol=RTOL, atol=1e-9)
    assert matrix[0, 30] == 0.0
    assert space.cost_matrix([], targets).shape == (0, 32)


def test_cost_matrix_rows_from_the_memo_match_path_costs(case: NetCase) -> None:
    """A second matrix over the same sources takes its rows from the memo; a memo
    too small for them evicts and computes again; both equal the compiled search."""
    rng = np.random.default_rng(26)
    sources = case.random_positions(rng, 25)
    first_targets = case.random_positions(rng, 10)
    targets = [*case.random_positions(rng, 20), sources[2], NetPosition(sources[3].edge, 0.0)]
    expected = np.array(
        [[RoadSpace(case.network).path_cost(s, t) for t in targets] for s in sources]
    )
    space = RoadSpace(case.network)
    space.cost_matrix(sources, first_targets)
    np.testing.assert_allclose(space.cost_matrix(sources, targets), expected, rtol=RTOL, atol=1e-9)
    edges = np.array(sorted({s.edge for s in sources}), dtype=np.int64)
    tiny = DistanceRows(case.network, space.edge_costs, max_bytes=3 * 8 * case.network.n_edges)
    uncached = DistanceRows(case.network, space.edge_costs, max_bytes=0).rows(edges)
    columns = np.array([5, 0, 5, case.network.n_edges - 1], dtype=np.int64)
    for _ in range(2):
        np.testing.assert_array_equal(tiny.rows(edges), uncached)
        np.testing.assert_array_equal(tiny.rows(edges[::-1]), uncached[::-1])
        # some rows from the memo, some computed: only the columns asked for, in order
        np.testing.assert_array_equal(tiny.rows_at(edges, columns), uncached[:, columns])
    assert len(tiny) == 3


def test_a_space_with_new_travel_times_does_not_reuse_old_rows(drt_case: NetCase) -> None:
    net = drt_case.network
    rng = np.random.default_rng(27)
    sources = drt_case.random_positions(rng, 20)
    targets = drt_case.random_positions(rng, 20)
    space = RoadSpace(net, cost="time")
    before = space.cost_matrix(sources, targets)
    slow = {net.edge_ids[e]: float(net.length[e] / net.speed[e] * 10.0) for e in range(net.n_edges)}
    slower = space.with_travel_times(slow)
    np.testing.assert_allclose(slower.cost_matrix(sources, targets), before * 10.0, rtol=RTOL)
    np.testing.assert_array_equal(space.cost_matrix(sources, targets), before)


def test_one_way_streets_make_costs_directed(oneway_case: NetCase) -> None:
    space = RoadSpace(oneway_case.network, either_way=False)
    rng = np.random.default_rng(23)
    points = oneway_case.random_positions(rng, 60)
    matrix = space.cost_matrix(points, points)
    assert np.abs(matrix - matrix.T).max() > 100.0


def test_time_costs_divide_lengths_by_speeds(drt_case: NetCase) -> None:
    net = drt_case.network
    space = RoadSpace(net, cost="time", either_way=False)
    rng = np.random.default_rng(24)
    for position in drt_case.random_positions(rng, 50):
        ahead = NetPosition(position.edge, net.length[position.edge])
        expected = (ahead.offset - position.offset) / net.speed[position.edge]
        np.testing.assert_allclose(space.path_cost(position, ahead), expected, rtol=RTOL)


def test_advance_walks_exactly_the_requested_cost(case: NetCase, space: RoadSpace) -> None:
    rng = np.random.default_rng(25)
    for _ in range(300):
        [position, target] = case.random_positions(rng, 2)
        if rng.random() < 0.3:  # same edge, target ahead or behind
            target = NetPosition(
                position.edge, float(rng.uniform(0, case.network.length[position.edge]))
            )
        result = space.assign(target, [position], np.ones(1), ONE)
        cost = result.mover_cost
        amount = float(rng.uniform(0.0, cost))
        moved = space.advance(position, target, result.route, amount)
        remaining = space.path_cost(moved, target)
        assert abs(remaining - (cost - amount)) <= RTOL * max(cost, 1.0)
        assert space.advance(position, target, result.route, cost) == target
        assert space.advance(position, target, result.route, 2 * cost + 1.0) == target
        assert space.advance(position, target, result.route, 0.0) == position


def test_advance_loops_around_to_a_target_behind(oneway_case: NetCase) -> None:
    space = RoadSpace(oneway_case.network, either_way=False)
    length = oneway_case.network.length[0]
    position, target = NetPosition(0, 0.75 * length), NetPosition(0, 0.25 * length)
    result = space.assign(target, [position], np.ones(1), ONE)
    route = np.asarray(result.route)
    assert route[0] == route[-1] == 0 and len(route) > 2
    cost = result.mover_cost
    for fraction in np.linspace(0.0, 1.0, 41):
        moved = space.advance(position, target, route, fraction * cost)
        assert abs(space.path_cost(moved, target) - (1 - fraction) * cost) <= RTOL * cost
    nudged = space.advance(position, target, route, 0.1 * length)
    assert nudged.edge == 0 and nudged.offset == pytest.approx(0.85 * length)


def test_advance_rejects_bad_routes_and_amounts(drt_case: NetCase) -> None:
    space = RoadSpace(drt_case.network, either_way=False)
    rng = np.random.default_rng(26)
    [position, target] = drt_case.random_positions(rng, 2)
    route = np.asarray(space.assign(target, [position], np.ones(1), ONE).route)
    for amount in (-1.0, float("nan"), float("inf")):
        with pytest.raises(InvalidInput, match="amount"):
            space.advance(position, target, route, amount)
    with pytest.raises(InvalidInput, match="route"):
        space.advance(position, target, route[::-1].copy(), 1.0)
    with pytest.raises(InvalidInput, match="route"):
        space.advance(position, target, [int(e) for e in route], 1.0)
    with pytest.raises(InvalidInput, match="offset must be a number"):
        space.advance(NetPosition(position.edge, "near"), target, route, 1.0)  # type: ignore[arg-type]
    if len(route) > 2:
        with pytest.raises(InvalidInput, match="not connected"):
            space.advance(position, target, np.delete(route, 1), 1.0)


def test_perturb_is_a_seeded_forward_walk(case: NetCase, space: RoadSpace) -> None:
    rng = np.random.default_rng(27)
    scale = space.typical_cost()
    for position in case.random_positions(rng, 100):
        amount = float(rng.uniform(0.0, scale))
        moved = space.perturb(position, amount, np.random.default_rng(5))
        assert moved == space.perturb(position, amount, np.random.default_rng(5))
        assert space.path_cost(position, moved) <= amount * (1 + RTOL) + 1e-9
        assert space.perturb(position, 0.0, np.random.default_rng(5)) == position
        room = case.network.length[position.edge] - position.offset
        step = space.perturb(position, room / 2, np.random.default_rng(5))
        assert step.edge == position.edge
        assert step.offset == pytest.approx(position.offset + room / 2)
    with pytest.raises(InvalidInput, match="amount"):
        space.perturb(NetPosition(0, 0.0), -1.0, np.random.default_rng(5))


def test_typical_cost_is_the_documented_median(case: NetCase, space: RoadSpace) -> None:
    net = case.network
    rng = np.random.default_rng(0)
    sources = rng.choice(net.n_edges, size=min(net.n_edges, 32), replace=False)
    targets = rng.choice(net.n_edges, size=min(net.n_edges, 256), replace=False)
    ref = case.reference
    costs = ref.edge_costs(kind="length")
    weighted = ref.weighted(costs)
    values = []
    for t in targets:
        target = (net.edge_ids[t], net.length[t] / 2)
        start = ref.start_costs(target, costs, weighted)
        values += [
            ref.vehicle_cost((net.edge_ids[s], net.length[s] / 2), target, costs, start)
            for s in sources
        ]
    assert space.typical_cost() == pytest.approx(float(np.median(values)), rel=RTOL)
    assert RoadSpace(net, either_way=False).typical_cost() == space.typical_cost()


def test_encode_decode_round_trip(case: NetCase, space: RoadSpace) -> None:
    rng = np.random.default_rng(28)
    for position in case.random_positions(rng, 200):
        data = json.loads(json.dumps(space.encode(position)))
        assert data["edge"] == case.network.edge_ids[position.edge]
        assert space.decode(data) == position


@pytest.mark.parametrize(
    ("data", "error"),
    [
        ({"edge": "no-such-edge", "offset": 1.0}, UnknownEdge),
        ({"offset": 1.0}, InvalidInput),
        ({"edge": "E"}, InvalidInput),
        ({"edge": 3, "offset": 1.0}, InvalidInput),
        ({"edge": "E", "offset": float("nan")}, InvalidInput),
        ({"edge": "E", "offset": float("inf")}, InvalidInput),
        ({"edge": "E", "offset": -0.5}, InvalidInput),
        ({"edge": "E", "offset": 1e9}, InvalidInput),
        ({"edge": "E", "offset": "1.0"}, InvalidInput),
        ({"edge": "E", "offset": True}, InvalidInput),
    ],
)
def test_decode_rejects_bad_data(drt_case: NetCase, data: dict[str, object], error: type) -> None:
    space = RoadSpace(drt_case.network, either_way=False)
    if data.get("edge") == "E":
        data = {**data, "edge": drt_case.network.edge_ids[0]}
    with pytest.raises(error):
        space.decode(data)


def test_xy_follows_the_edge_shape(case: NetCase, space: RoadSpace) -> None:
    net = case.network
    for edge in range(0, net.n_edges, 7):
        points = net.shape_xy[net.shape_offsets[edge] : net.shape_offsets[edge + 1]]
        assert space.xy(NetPosition(edge, 0.0)) == pytest.approx(tuple(points[0]))
        assert space.xy(NetPosition(edge, float(net.length[edge]))) == pytest.approx(
            tuple(points[-1])
        )
        along = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))))
        middle = space.xy(NetPosition(edge, float(net.length[edge] / 2)))
        half = along[-1] / 2
        k = int(np.searchsorted(along, half, side="right")) - 1
        k = min(k, len(points) - 2)
        share = (half - along[k]) / (along[k + 1] - along[k]) if along[k + 1] > along[k] else 0.0
        expected = points[k] + share * (points[k + 1] - points[k])
        assert middle == pytest.approx(tuple(expected))


def test_lonlat_lies_in_the_mapped_area(drt_case: NetCase, oneway_case: NetCase) -> None:
    space = RoadSpace(drt_case.network, either_way=False)
    rng = np.random.default_rng(29)
    for position in drt_case.random_positions(rng, 50):
        lon, lat = space.lonlat(position)
        assert 13.44 < lon < 13.59 and 52.41 < lat < 52.47
    with pytest.raises(InvalidInput, match="projection"):
        RoadSpace(oneway_case.network, either_way=False).lonlat(NetPosition(0, 0.0))


def test_with_travel_times_validates_and_leaves_the_original(drt_case: NetCase) -> None:
    net = drt_case.network
    timed = RoadSpace(net, cost="time", either_way=False)
    before = timed.edge_costs.cost.copy()
    slower = timed.with_travel_times({net.edge_ids[0]: 1000.0})
    assert slower.edge_costs.cost[0] == 1000.0
    np.testing.assert_array_equal(timed.edge_costs.cost, before)
    assert slower.network is net
    with pytest.raises(InvalidInput, match="cost='time'"):
        RoadSpace(net, either_way=False).with_travel_times({net.edge_ids[0]: 1.0})
    with pytest.raises(UnknownEdge):
        timed.with_travel_times({"no-such-edge": 1.0})
    for bad in (0.0, -1.0, float("nan"), float("inf"), "fast", True):
        with pytest.raises(InvalidInput):
            timed.with_travel_times({net.edge_ids[0]: bad})  # type: ignore[dict-item]
    with pytest.raises(InvalidInput, match="cost must be"):
        RoadSpace(net, cost="fuel")  # type: ignore[arg-type]


def _walk_reference(
    case: NetCase,
    space: RoadSpace,
    position: NetPosition,
    target: NetPosition,
    route: np.ndarray,
    amount: float,
) -> NetPosition:
    """The walk written with numpy's cumulative sums (sequential, like the walk's loops)."""
    net, rate, cost = case.network, space.edge_costs.rate, space.edge_costs.cost
    if route.shape[0] == 1:
        if amount >= (target.offset - position.offset) * rate[target.edge]:
            return target
        offset = min(position.offset + amount / rate[target.edge], target.offset)
        return NetPosition(target.edge, float(offset))
    first = int(route[0])
    segments = np.empty(route.shape[0])
    segments[0] = (net.length[first] - position.offset) * rate[first]
    segments[1:-1] = cost[route[1:-1]]
    segments[-1] = target.offset * rate[target.edge]
    reached = np.cumsum(segments)
    if amount >= reached[-1] or amount >= np.cumsum(segments[:0:-1])[-1] + segments[0]:
        return target
    k = int(np.searchsorted(reached, amount, side="right"))
    if k == 0:
        return NetPosition(
            first, float(min(position.offset + amount / rate[first], net.length[first]))
        )
    edge = int(route[k])
    limit = target.offset if k == route.shape[0] - 1 else net.length[edge]
    return NetPosition(edge, float(min((amount - reached[k - 1]) / rate[edge], limit)))


def test_advance_matches_a_numpy_walk_bit_for_bit(case: NetCase) -> None:
    """1,000 routes (length and time costs), amounts short of, at and past the ends of
    their edges."""
    rng = np.random.default_rng(28)
    for kind in ("length", "time"):
        space = RoadSpace(case.network, cost=kind, either_way=False)
        for _ in range(500):
            [position, target] = case.random_positions(rng, 2)
            result = space.assign(target, [position], np.ones(1), ONE)
            route = np.asarray(result.route)
            cost = result.mover_cost
            first_rest = (case.network.length[route[0]] - position.offset) * float(
                space.edge_costs.rate[route[0]]
            )
            for amount in (float(rng.uniform(0.0, cost)), first_rest, cost, 0.5 * cost):
                expected = _walk_reference(case, space, position, target, route, amount)
                moved = space.advance(position, target, route, amount)
                assert moved == expected
                assert type(moved.edge) is int and type(moved.offset) is float


def test_an_unpickled_space_is_kept_for_the_same_network_and_costs(drt_case: NetCase) -> None:
    """A worker that unpickles job after job keeps one space, and its memoised rows, per
    network, costs and turning rule; other travel times give another space."""
    net = drt_case.network
    rng = np.random.default_rng(28)
    sources, targets = drt_case.random_positions(rng, 10), drt_case.random_positions(rng, 10)
    space = RoadSpace(net, cost="time")
    first = pickle.loads(pickle.dumps(space))
    assert pickle.loads(pickle.dumps(space)) is first
    slower = space.with_travel_times({net.edge_ids[0]: float(net.length[0] / net.speed[0] * 3)})
    other = pickle.loads(pickle.dumps(slower))
    assert other is not first
    np.testing.assert_array_equal(other.edge_costs.cost, slower.edge_costs.cost)
    np.testing.assert_array_equal(
        first.cost_matrix(sources, targets), space.cost_matrix(sources, targets)
    )
    np.testing.assert_array_equal(
        other.cost_matrix(sources, targets), slower.cost_matrix(sources, targets)
    )


def test_distance_to_an_edge_start_is_the_least_over_its_predecessors_by_hand() -> None:
    to_ends = np.array([[3.0, 1.0, np.inf, 7.0], [0.5, 2.0, 4.0, np.inf]])
    # edge 0 <- {0, 1}; edge 1 <- none; edge 2 <- {3}; edge 3 <- {2}
    indptr = np.array([0, 2, 2, 3, 4], dtype=np.int32)
    preds = np.array([0, 1, 3, 2], dtype=np.int32)
    out = np.empty_like(to_ends)
    _least_over_predecessors(to_ends, indptr, preds, out)
    np.testing.assert_array_equal(out, [[1.0, np.inf, 7.0, np.inf], [0.5, np.inf, np.inf, 4.0]])


@pytest.mark.parametrize("zeroed", [0.0, 0.2])
def test_edge_end_rows_equal_scipy_dijkstra_bit_for_bit(
    case: NetCase, space: RoadSpace, zeroed: float
) -> None:
    """The compiled rows against scipy's Dijkstra on the same arcs (arc ``x -> y`` weighs
    ``cost[y]``), some edges costing nothing, and with the sources split between threads."""
    network = case.network
    rng = np.random.default_rng(23)
    cost = space.edge_costs.cost.copy()
    cost[rng.random(network.n_edges) < zeroed] = 0.0
    costs = EdgeCosts(space.edge_costs.kind, cost, space.edge_costs.rate)
    graph = csr_matrix(
        (cost[network.fwd_indices], network.fwd_indices, network.fwd_indptr),
        shape=(network.n_edges, network.n_edges),
    )
    for n_sources in (3, 2 * _ROWS_PER_THREAD + 5):
        sources = rng.integers(network.n_edges, size=n_sources).astype(np.int64)
        expected = dijkstra(graph, directed=True, indices=sources)
        rows = DistanceRows(network, costs, max_bytes=0)._edge_end_rows(sources)
        np.testing.assert_array_equal(rows, expected)
