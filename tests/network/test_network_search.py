"""The nearest-vehicle search (RoadSpace.assign) against networkx on random queries."""

from __future__ import annotations

import numpy as np
import pytest

from routing_svc.errors import InvalidInput, UnmetRequirement, Unreachable
from routing_svc.network import CompiledNetwork, NetworkReduction, RoadSpace
from routing_svc.sa.space import Requirement
from routing_svc.types import NetPosition
from tests.helpers import check_assignment, reference_times, run_queries
from tests.network.conftest import NetCase


def test_nearest_vehicle_matches_networkx(case: NetCase, space: RoadSpace) -> None:
    rng = np.random.default_rng(11)
    positions = case.random_positions(rng, 40)
    requirement = Requirement(np.zeros(40, dtype=np.int64), np.ones(1, dtype=np.int64))
    run_queries(
        case,
        space,
        rng,
        n_targets=1000,
        positions=positions,
        speeds=np.ones(40),
        requirement=requirement,
        costs=case.reference.edge_costs(kind="length"),
    )


def test_groups_counts_and_speeds_match_networkx(case: NetCase, space: RoadSpace) -> None:
    rng = np.random.default_rng(12)
    n = 60
    positions = case.random_positions(rng, n)
    groups = rng.integers(-1, 3, size=n)
    groups[:9] = [0, 0, 0, 1, 1, 2, 2, 2, 2]  # every group can be served
    requirement = Requirement(groups, np.array([2, 1, 3]))
    run_queries(
        case,
        space,
        rng,
        n_targets=300,
        positions=positions,
        speeds=rng.uniform(0.3, 3.0, n),
        requirement=requirement,
        costs=case.reference.edge_costs(kind="length"),
    )


def test_targets_on_vehicle_edges(case: NetCase, space: RoadSpace) -> None:
    """Targets just ahead of and just behind vehicles on the same edge."""
    rng = np.random.default_rng(13)
    costs = case.reference.edge_costs(kind="length")
    weighted = case.reference.weighted(costs)
    requirement = Requirement(np.array([0, 0, 1, 1]), np.array([1, 1]))
    speeds = np.array([1.0, 1.7, 0.8, 1.0])
    for _ in range(300):
        [vehicle, other, third] = case.random_positions(rng, 3)
        length = case.network.length[vehicle.edge]
        shift = float(rng.uniform(0.0, length)) * rng.choice([-1.0, 1.0, 0.0])
        target = NetPosition(vehicle.edge, float(np.clip(vehicle.offset + shift, 0.0, length)))
        behind = NetPosition(vehicle.edge, float(rng.uniform(target.offset, length)))
        positions = [vehicle, other, behind, third]
        result = space.assign(target, positions, speeds, requirement)
        ref_cost, ref_time = reference_times(case, costs, weighted, target, positions, speeds)
        check_assignment(case, space, result, target, positions, requirement, ref_cost, ref_time)


def test_replaced_travel_times_match_networkx(case: NetCase) -> None:
    rng = np.random.default_rng(14)
    net = case.network
    chosen = rng.choice(net.n_edges, size=net.n_edges // 3, replace=False)
    free = net.length / net.speed
    times = {net.edge_ids[e]: float(free[e] * rng.uniform(0.2, 8.0)) for e in chosen}
    space = RoadSpace(net, cost="time", either_way=False).with_travel_times(times)
    n = 30
    positions = case.random_positions(rng, n)
    groups = np.arange(n) % 2
    requirement = Requirement(groups, np.array([1, 2]))
    run_queries(
        case,
        space,
        rng,
        n_targets=300,
        positions=positions,
        speeds=rng.uniform(0.5, 2.0, n),
        requirement=requirement,
        costs=case.reference.edge_costs(kind="time", times=times),
    )


def test_ties_break_by_lower_index(drt_case: NetCase) -> None:
    space = RoadSpace(drt_case.network, either_way=False)
    rng = np.random.default_rng(15)
    [near, far, target] = drt_case.random_positions(rng, 3)
    positions = [far, near, far, near, near]
    one = Requirement(np.zeros(5, dtype=np.int64), np.array([1]))
    result = space.assign(target, positions, np.ones(5), one)
    expected = 1 if space.path_cost(near, target) <= space.path_cost(far, target) else 0
    assert result.served_by == (expected,)
    three = Requirement(np.zeros(5, dtype=np.int64), np.array([3]))
    served = space.assign(target, positions, np.ones(5), three).served_by
    assert served == ((1, 3, 4) if expected == 1 else (0, 2, 1))


def test_assign_is_pure_and_recovers_from_errors(drt_case: NetCase) -> None:
    space = RoadSpace(drt_case.network, either_way=False)
    rng = np.random.default_rng(16)
    positions = drt_case.random_positions(rng, 20)
    requirement = Requirement(np.arange(20) % 2, np.array([2, 2]))
    targets = drt_case.random_positions(rng, 30)
    first = [space.assign(t, positions, np.ones(20), requirement) for t in targets]
    with pytest.raises(InvalidInput):
        space.assign(targets[0], [*positions[:-1], NetPosition(0, -1.0)], np.ones(20), requirement)
    with pytest.raises(UnmetRequirement):
        space.assign(
            targets[0], positions, np.ones(20), Requirement(np.arange(20) % 2, np.array([11, 1]))
        )
    again = [space.assign(t, positions, np.ones(20), requirement) for t in targets]
    for a, b in zip(first, again, strict=True):
        assert (a.served_by, a.times, a.mover, a.mover_cost) == (
            b.served_by,
            b.times,
            b.mover,
            b.mover_cost,
        )
        np.testing.assert_array_equal(a.route, b.route)


def chain_network() -> CompiledNetwork:
    """Two edges a -> b and nothing back: b cannot reach a."""
    one = np.ones(1, dtype=np.int32)
    return CompiledNetwork(
        vclass="passenger",
        source_sha256="0" * 64,
        edge_ids=("a", "b"),
        length=np.array([100.0, 50.0]),
        speed=np.array([10.0, 10.0]),
        edge_from=np.array([0, 1], dtype=np.int32),
        edge_to=np.array([1, 2], dtype=np.int32),
        junction_ids=("j0", "j1", "j2"),
        fwd_indptr=np.array([0, 1, 1], dtype=np.int32),
        fwd_indices=one,
        rev_indptr=np.array([0, 0, 1], dtype=np.int32),
        rev_indices=np.zeros(1, dtype=np.int32),
        shape_xy=np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 0.0], [150.0, 0.0]]),
        shape_offsets=np.array([0, 2, 4], dtype=np.int32),
        bounds=(0.0, 0.0, 150.0, 0.0),
        projection=None,
        reduction=NetworkReduction(usable_edges=2, kept_edges=2, dropped_edges=0, components=2),
    )


def test_unreachable_and_unmet_requirements() -> None:
    space = RoadSpace(chain_network())
    on_a, on_b = NetPosition(0, 10.0), NetPosition(1, 10.0)
    any_one = Requirement(np.zeros(1, dtype=np.int64), np.array([1]))
    with pytest.raises(Unreachable):
        space.assign(on_a, [on_b], np.ones(1), any_one)
    with pytest.raises(Unreachable):
        space.assign(NetPosition(1, 5.0), [on_b], np.ones(1), any_one)
    result = space.assign(
        on_b, [on_a, on_b], np.ones(2), Requirement(np.array([0, 1]), np.array([1, 1]))
    )
    assert result.served_by == (0, 1)
    assert result.times == (100.0, 0.0)
    assert result.mover == 0
    np.testing.assert_array_equal(result.route, [0, 1])
    with pytest.raises(UnmetRequirement):
        space.assign(
            on_b, [on_a, on_b], np.ones(2), Requirement(np.array([0, -1]), np.array([1, 1]))
        )
    with pytest.raises(Unreachable):
        space.path_cost(on_b, on_a)


@pytest.mark.parametrize(
    ("target", "positions", "speeds", "groups", "counts", "message"),
    [
        (NetPosition(2, 0.0), [NetPosition(0, 1.0)], [1.0], [0], [1], "target"),
        (NetPosition(0, float("nan")), [NetPosition(0, 1.0)], [1.0], [0], [1], "target"),
        (NetPosition(0, 101.0), [NetPosition(0, 1.0)], [1.0], [0], [1], "target"),
        (NetPosition(0, 1.0), [NetPosition(0, float("inf"))], [1.0], [0], [1], "vehicle 0"),
        (NetPosition(0, 1.0), [NetPosition(-1, 1.0)], [1.0], [0], [1], "vehicle 0"),
        (NetPosition(0, 1.0), [NetPosition(0, 1.0)], [0.0], [0], [1], "speed"),
        (NetPosition(0, 1.0), [NetPosition(0, 1.0)], [float("nan")], [0], [1], "speed"),
        (NetPosition(0, 1.0), [NetPosition(0, 1.0)], [-2.0], [0], [1], "speed"),
        (NetPosition(0, 1.0), [NetPosition(0, 1.0)], [1.0, 1.0], [0], [1], "speeds"),
        (NetPosition(0, 1.0), [NetPosition(0, 1.0)], [1.0], [0, 0], [1], "group per vehicle"),
        (NetPosition(0, 1.0), [NetPosition(0, 1.0)], [1.0], [3], [1], "outside"),
        (NetPosition(0, 1.0), [NetPosition(0, 1.0)], [1.0], [0], [0], "at least one"),
        (NetPosition(0, 1.0), [NetPosition(0, 1.0)], [1.0], [0], [-1], "at least one"),
        (NetPosition(0, 1.0), [(0.5, 1.0)], [1.0], [0], [1], "integer edge"),
    ],
)
def test_invalid_input_is_rejected(
    target: NetPosition,
    positions: list[NetPosition],
    speeds: list[float],
    groups: list[int],
    counts: list[int],
    message: str,
) -> None:
    space = RoadSpace(chain_network())
    requirement = Requirement(np.array(groups), np.array(counts))
    with pytest.raises(InvalidInput, match=message):
        space.assign(target, positions, np.array(speeds), requirement)
