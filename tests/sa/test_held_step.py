"""The paper's step held until it reaches a window (``held_step``) and the junctions it stops at.

The hand-made net has four junctions and six edges (lengths in metres)::

    a  : j0 -> j1  100  one-way
    b  : j1 -> j2  100  two-way with nb
    nb : j2 -> j1  100
    c  : j1 -> j3  100  one-way
    d  : j3 -> j0  150  one-way
    f  : j2 -> j0  200  one-way

with the turns a->b, a->c, b->nb, b->f, nb->c, nb->b, c->d, d->a, f->a. At j1 a
reference at the end of ``a`` (the same place as the start of ``b`` and the end
of ``nb``) can leave by ``b`` or by ``c``: two exits whose next junctions are
``(b, 100)`` and ``(c, 100)``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork, RoadSpace, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.sa.held_step import Hold, JunctionSpace, held_step
from routing_svc.sa.space import Requirement
from routing_svc.types import NetPosition
from tests.sa.conftest import hand_made_net_xml

_XY = {"j0": (0.0, 0.0), "j1": (100.0, 0.0), "j2": (200.0, 0.0), "j3": (100.0, 100.0)}
_EDGES = {
    "a": ("j0", "j1", 100.0),
    "b": ("j1", "j2", 100.0),
    "nb": ("j2", "j1", 100.0),
    "c": ("j1", "j3", 100.0),
    "d": ("j3", "j0", 150.0),
    "f": ("j2", "j0", 200.0),
}
_TURNS = [
    ("a", "b"), ("a", "c"), ("b", "nb"), ("b", "f"), ("nb", "c"), ("nb", "b"),
    ("c", "d"), ("d", "a"), ("f", "a"),
]  # fmt: skip
_ONE = Requirement(np.zeros(1, dtype=np.int64), np.ones(1, dtype=np.int64))


def _net_xml() -> str:
    return hand_made_net_xml(_XY, _EDGES, _TURNS)


@pytest.fixture(scope="module")
def network(tmp_path_factory: pytest.TempPathFactory) -> CompiledNetwork:
    folder: Path = tmp_path_factory.mktemp("held_net")
    path = folder / "junction.net.xml"
    path.write_text(_net_xml())
    return load_network(path, cache_dir=folder / "cache")


@pytest.fixture(scope="module")
def space(network: CompiledNetwork) -> RoadSpace:
    return RoadSpace(network, cost="length")


@pytest.fixture(scope="module")
def drt() -> RoadSpace:
    return RoadSpace(load_network(resolve_network("drt")), cost="length")


def at(network: CompiledNetwork, edge: str, offset: float) -> NetPosition:
    return NetPosition(network.edge_ids.index(edge), float(offset))


def route_to(space: RoadSpace, source: NetPosition, target: NetPosition) -> tuple[object, float]:
    found = space.assign(target, [source], np.ones(1), _ONE)
    return found.route, found.mover_cost


def step(
    space: RoadSpace,
    source: NetPosition,
    target: NetPosition,
    *,
    amount: float,
    hold: Hold[NetPosition] | None = None,
    window: float = 10.0,
) -> tuple[NetPosition, float, Hold[NetPosition] | None]:
    route, cost = route_to(space, source, target)
    return held_step(
        space, source, target, route, amount=amount, path_cost=cost, hold=hold, window=window
    )


def test_the_net_is_the_one_described(network: CompiledNetwork, space: RoadSpace) -> None:
    assert sorted(network.edge_ids) == sorted(_EDGES)
    for edge, (_, _, length) in _EDGES.items():
        assert network.length[network.edge_ids.index(edge)] == length
    assert isinstance(space, JunctionSpace)
    # from the end of a: b and c are both one edge away
    assert space.path_cost(at(network, "a", 100.0), at(network, "b", 50.0)) == 50.0
    assert space.path_cost(at(network, "a", 100.0), at(network, "c", 50.0)) == 50.0
    # from inside c, c is reached again only around the loop d, a
    assert space.path_cost(at(network, "c", 60.0), at(network, "c", 50.0)) == 40 + 150 + 100 + 50


# -- a reference between junctions ---------------------------------------------------


@pytest.mark.parametrize("amount", [10.0, 30.0, 79.5])
def test_mid_edge_a_step_of_the_window_or_more_moves_as_the_paper_does(
    network: CompiledNetwork, space: RoadSpace, amount: float
) -> None:
    source, target = at(network, "a", 20.0), at(network, "b", 50.0)
    route, cost = route_to(space, source, target)
    assert cost == 130.0  # 80 to j1, 50 along b
    new, moved, hold = step(space, source, target, amount=amount, window=10.0)
    assert new == at(network, "a", 20.0 + amount)
    assert new == space.advance(source, target, route, amount)
    assert moved == amount
    assert hold is None


@pytest.mark.parametrize("amount", [0.0, 4.0, 9.5])
def test_mid_edge_a_step_below_the_window_only_records_pressure(
    network: CompiledNetwork, space: RoadSpace, amount: float
) -> None:
    # a reference on a demand point pays a jump for any move past it, as on a junction
    source, target = at(network, "a", 20.0), at(network, "b", 50.0)
    new, moved, hold = step(space, source, target, amount=amount, window=10.0)
    assert (new, moved) == (source, 0.0)
    assert hold == Hold(at(network, "a", 100.0), amount)
    # a second step in the same direction completes the window: the whole pressure moves
    new, moved, hold = step(space, new, target, amount=10.0 - amount, hold=hold, window=10.0)
    assert (new, moved, hold) == (at(network, "a", 30.0), 10.0, None)


@pytest.mark.parametrize("amount", [80.0, 80.5, 120.0, 130.0, 1e9])
def test_mid_edge_stops_on_the_junction_ahead(
    network: CompiledNetwork, space: RoadSpace, amount: float
) -> None:
    source, target = at(network, "a", 20.0), at(network, "b", 50.0)
    new, moved, hold = step(space, source, target, amount=amount)
    # j1 is the end of a: the reference stops there, 80 m moved, whatever the amount
    assert new == at(network, "a", float(network.length[network.edge_ids.index("a")]))
    assert moved == 80.0
    assert hold is None


def test_mid_edge_leaving_by_the_twin_stops_at_the_twins_end(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    # (b, 40) reaches c by turning around onto nb at (nb, 60): 40 m to j1, then 30 along c
    source, target = at(network, "b", 40.0), at(network, "c", 30.0)
    route, cost = route_to(space, source, target)
    assert [network.edge_ids[e] for e in np.asarray(route).tolist()] == ["nb", "c"]
    assert cost == 70.0
    assert step(space, source, target, amount=15.0) == (at(network, "nb", 75.0), 15.0, None)
    assert step(space, source, target, amount=60.0) == (at(network, "nb", 100.0), 40.0, None)


def test_target_ahead_on_the_same_edge_is_not_passed(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    source, target = at(network, "a", 20.0), at(network, "a", 60.0)
    route, cost = route_to(space, source, target)
    assert cost == 40.0
    # the step of eq. (10) is at most D: the reference ends on the target
    assert step(space, source, target, amount=40.0) == (target, 40.0, None)
    assert step(space, source, target, amount=10.0) == (at(network, "a", 30.0), 10.0, None)
    new, moved, _ = held_step(
        space, source, target, route, amount=75.0, path_cost=cost, hold=None, window=10.0
    )
    assert (new, moved) == (target, 40.0)


# -- a reference on a junction -----------------------------------------------------


def test_a_step_below_the_window_only_records_pressure(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    source = at(network, "a", 100.0)
    new, moved, hold = step(space, source, at(network, "b", 50.0), amount=4.0, window=10.0)
    assert (new, moved) == (source, 0.0)
    assert hold == Hold(at(network, "b", 100.0), 4.0)


def test_steps_toward_one_exit_add_up_and_leave_at_the_window(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    source, target = at(network, "a", 100.0), at(network, "b", 50.0)
    new, moved, hold = step(space, source, target, amount=4.0)
    new, moved, hold = step(space, new, target, amount=5.0, hold=hold)
    assert (new, moved, hold) == (source, 0.0, Hold(at(network, "b", 100.0), 9.0))
    # 9 + 3 = 12 >= 10: it leaves by b, the whole pressure along the path
    new, moved, hold = step(space, new, target, amount=3.0, hold=hold)
    assert (new, moved, hold) == (at(network, "b", 12.0), 12.0, None)


def test_exactly_the_window_leaves(network: CompiledNetwork, space: RoadSpace) -> None:
    source, target = at(network, "a", 100.0), at(network, "b", 50.0)
    held = Hold(at(network, "b", 100.0), 6.0)
    assert step(space, source, target, amount=4.0, hold=held) == (
        at(network, "b", 10.0),
        10.0,
        None,
    )


def test_leaving_moves_at_most_to_the_target(network: CompiledNetwork, space: RoadSpace) -> None:
    source, target = at(network, "a", 100.0), at(network, "b", 50.0)
    held = Hold(at(network, "b", 100.0), 9.0)
    # pressure 9 + 41 = 50 = D: exactly the target; 9 + 200: still min(pressure, D) = 50
    assert step(space, source, target, amount=41.0, hold=held) == (target, 50.0, None)
    assert step(space, source, target, amount=200.0, hold=held) == (target, 50.0, None)


def test_leaving_never_passes_the_next_junction(network: CompiledNetwork, space: RoadSpace) -> None:
    source, target = at(network, "a", 100.0), at(network, "f", 50.0)
    route, cost = route_to(space, source, target)
    assert [network.edge_ids[e] for e in np.asarray(route).tolist()] == ["a", "b", "f"]
    assert cost == 150.0
    held = Hold(at(network, "b", 100.0), 9.0)
    # pressure 120 < D = 150, but j2 (the end of b) is 100 away: it stops there
    assert step(space, source, target, amount=111.0, hold=held) == (
        at(network, "b", 100.0),
        100.0,
        None,
    )
    # pressure 60: along b, short of j2
    new, moved, hold = step(space, source, target, amount=51.0, hold=held)
    assert (new, moved, hold) == (at(network, "b", 60.0), 60.0, None)
    assert new == space.advance(source, target, route, 60.0)


def test_a_step_toward_another_exit_takes_from_the_pressure(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    source = at(network, "a", 100.0)
    to_b, to_c = at(network, "b", 50.0), at(network, "c", 50.0)
    exit_b, exit_c = at(network, "b", 100.0), at(network, "c", 100.0)
    new, moved, hold = step(space, source, to_b, amount=6.0)
    assert hold == Hold(exit_b, 6.0)
    # 4 toward c: the majority still leans to b, by 2
    new, moved, hold = step(space, new, to_c, amount=4.0, hold=hold)
    assert (new, moved, hold) == (source, 0.0, Hold(exit_b, 2.0))
    # 5 toward c: c now leads by 3, below the window
    new, moved, hold = step(space, new, to_c, amount=5.0, hold=hold)
    assert (new, moved, hold) == (source, 0.0, Hold(exit_c, 3.0))
    # 8 more toward c: 11 >= 10, it leaves along c
    new, moved, hold = step(space, new, to_c, amount=8.0, hold=hold)
    assert (new, moved, hold) == (at(network, "c", 11.0), 11.0, None)


def test_a_step_toward_another_exit_can_leave_at_once(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    source = at(network, "a", 100.0)
    held = Hold(at(network, "b", 100.0), 3.0)
    # 15 toward c against 3 toward b: the vote is 12 for c, past the window
    assert step(space, source, at(network, "c", 50.0), amount=15.0, hold=held) == (
        at(network, "c", 12.0),
        12.0,
        None,
    )


def test_a_two_way_start_is_a_junction_with_both_exits(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    source = at(network, "b", 0.0)  # the same place as the end of nb, at j1
    assert step(space, source, at(network, "b", 30.0), amount=4.0) == (
        source,
        0.0,
        Hold(at(network, "b", 100.0), 4.0),
    )
    # toward c it leaves by turning onto nb: exit c, pressure from scratch
    assert step(space, source, at(network, "c", 30.0), amount=4.0) == (
        source,
        0.0,
        Hold(at(network, "c", 100.0), 4.0),
    )
    # with enough pressure toward b it leaves along b, up to the target
    new, moved, hold = step(
        space, source, at(network, "b", 30.0), amount=25.0, hold=Hold(at(network, "b", 100.0), 9.0)
    )
    assert (new, moved, hold) == (at(network, "b", 30.0), 30.0, None)


def test_a_junction_step_does_not_depend_on_a_pressure_of_zero(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    # a zero step leaves everything as it was (the pressure toward b is unchanged)
    source = at(network, "a", 100.0)
    held = Hold(at(network, "b", 100.0), 5.0)
    assert step(space, source, at(network, "b", 50.0), amount=0.0, hold=held) == (
        source,
        0.0,
        held,
    )


@pytest.mark.parametrize(
    ("amount", "window"),
    [
        (math.nan, 10.0),
        (-1.0, 10.0),
        (math.inf, 10.0),
        (1.0, 0.0),
        (1.0, -2.0),
        (1.0, math.nan),
        (1.0, math.inf),
    ],
)
def test_bad_amount_or_window(
    network: CompiledNetwork, space: RoadSpace, amount: float, window: float
) -> None:
    for source in (at(network, "a", 20.0), at(network, "a", 100.0)):
        with pytest.raises(InvalidInput):
            step(space, source, at(network, "b", 50.0), amount=amount, window=window)


# -- junction_ahead --------------------------------------------


def test_junction_ahead_on_the_hand_made_net(network: CompiledNetwork, space: RoadSpace) -> None:
    cases = [
        # source, target, junction ahead, its cost
        (("a", 20.0), ("b", 50.0), ("a", 100.0), 80.0),
        (("a", 20.0), ("a", 60.0), ("a", 100.0), 80.0),  # the end of the own edge
        (("a", 100.0), ("b", 50.0), ("b", 100.0), 100.0),  # at j1: the next one on b
        (("a", 100.0), ("c", 50.0), ("c", 100.0), 100.0),
        (("b", 0.0), ("c", 30.0), ("c", 100.0), 100.0),  # through the twin nb
        (("b", 40.0), ("c", 30.0), ("nb", 100.0), 40.0),  # turning around onto nb
        (("c", 60.0), ("c", 50.0), ("c", 100.0), 40.0),  # the target is behind
    ]
    for source, target, junction, cost in cases:
        route, _ = route_to(space, at(network, *source), at(network, *target))
        assert space.junction_ahead(at(network, *source), route) == (
            at(network, *junction),
            cost,
        ), (source, target)


def test_junction_ahead_rejects_a_bad_route(network: CompiledNetwork, space: RoadSpace) -> None:
    for bad in (np.array([], dtype=np.int64), [0, 1], np.zeros((1, 1), dtype=np.int64)):
        with pytest.raises(InvalidInput):
            space.junction_ahead(at(network, "a", 20.0), bad)


def test_junction_ahead_on_random_routes(drt: RoadSpace) -> None:
    net = drt.network
    rng = np.random.default_rng(2024)
    edges = rng.integers(net.n_edges, size=(300, 2))
    fractions = rng.choice([0.0, 0.3, 0.7, 1.0], size=(300, 2))
    seen_twin = seen_end = 0
    for (e, t), (fe, ft) in zip(edges.tolist(), fractions.tolist(), strict=True):
        source = NetPosition(e, float(net.length[e]) * fe)
        target = NetPosition(t, float(net.length[t]) * ft)
        if source == target:
            continue
        found = drt.assign(target, [source], np.ones(1), _ONE)
        route = np.asarray(found.route).tolist()
        ahead = drt.junction_ahead(source, found.route)
        # reference from the arrays: where the vehicle stands on the route's first edge
        first = route[0]
        if first == e:
            offset = source.offset
        else:  # it turns around onto the twin, which joins the same junctions the other way
            assert (int(net.edge_from[first]), int(net.edge_to[first])) == (
                int(net.edge_to[e]),
                int(net.edge_from[e]),
            )
            offset = float(net.length[first]) * (1.0 - fe)
            seen_twin += 1
        if offset < float(net.length[first]) - 1e-9:
            expected_edge, expected_cost = first, float(net.length[first]) - offset
        else:  # already on a junction: the end of the next edge of the route
            seen_end += 1
            assert len(route) >= 2
            expected_edge, expected_cost = route[1], float(net.length[route[1]])
        assert ahead is not None
        junction, cost = ahead
        assert junction == NetPosition(expected_edge, float(net.length[expected_edge]))
        assert cost == pytest.approx(expected_cost, rel=1e-12, abs=1e-9)
        # the junction lies on a shortest path to the target: its cost is the search's
        assert cost == pytest.approx(drt.path_cost(source, junction), rel=1e-9, abs=1e-6)
        if junction.edge != route[-1]:  # a junction before the target's edge
            assert cost <= found.mover_cost + 1e-9
    assert seen_twin > 10 and seen_end > 10
