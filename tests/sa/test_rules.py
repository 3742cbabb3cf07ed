"""Update rules and schedules against hand-computed values."""

from __future__ import annotations

import math

import pytest

from routing_svc.errors import InvalidInput
from routing_svc.sa import (
    COVERAGE,
    ROUTING,
    Constant,
    EuclideanPlane,
    Floor,
    InverseScaling,
    Objective,
    default_schedule,
    schedule_from_dict,
)
from routing_svc.types import PlanePosition


def test_routing_step_is_unit_subgradient_truncated_at_target() -> None:
    assert ROUTING.step_amount(gamma=0.3, path_cost=5.0, speed=1.0) == 0.3
    assert ROUTING.step_amount(gamma=7.0, path_cost=5.0, speed=1.0) == 5.0
    # a vehicle twice as fast: the gradient of E[D/v] is 1/v
    assert ROUTING.step_amount(gamma=0.3, path_cost=5.0, speed=2.0) == 0.15


def test_coverage_step_moves_gamma_times_distance() -> None:
    assert COVERAGE.step_amount(gamma=0.25, path_cost=8.0, speed=1.0) == 2.0
    assert COVERAGE.step_amount(gamma=1.0, path_cost=8.0, speed=1.0) == 8.0
    # T = 8/2 = 4, amount = gamma * T / v = 0.25 * 4 / 2
    assert COVERAGE.step_amount(gamma=0.25, path_cost=8.0, speed=2.0) == 0.5


def test_power_step() -> None:
    q = Objective(1.5)
    assert q.step_amount(gamma=0.5, path_cost=4.0, speed=1.0) == pytest.approx(0.5 * 2.0)
    assert q.cost(4.0) == pytest.approx(8.0)
    assert Objective.parse("coverage") == COVERAGE
    assert Objective.parse("1.5").power == 1.5
    assert Objective.parse(3).name == "power:3.0"


@pytest.mark.parametrize("bad", [0.5, math.nan, math.inf, "fast", True])
def test_bad_objectives(bad: object) -> None:
    with pytest.raises(InvalidInput):
        Objective.parse(bad)  # type: ignore[arg-type]


def test_plane_routing_step_by_hand() -> None:
    plane = EuclideanPlane(side=10.0)
    p = PlanePosition(0.0, 0.0)
    z = PlanePosition(3.0, 4.0)
    new = plane.advance(p, z, None, ROUTING.step_amount(gamma=1.0, path_cost=5.0, speed=1.0))
    assert new == pytest.approx(PlanePosition(0.6, 0.8), abs=1e-15)
    new = plane.advance(p, z, None, COVERAGE.step_amount(gamma=0.5, path_cost=5.0, speed=1.0))
    assert new == PlanePosition(1.5, 2.0)
    assert plane.advance(p, z, None, 9.0) == z


def test_schedule_values() -> None:
    s = InverseScaling(2.0, 1.0)
    assert [s(k) for k in range(4)] == [2.0, 1.0, 2.0 / 3.0, 0.5]
    assert InverseScaling(1.0, 0.75)(15) == pytest.approx(16**-0.75)
    assert Constant(0.1)(10**6) == 0.1
    f = Floor(InverseScaling(1.0, 1.0), 0.05)
    assert f(0) == 1.0 and f(9) == pytest.approx(0.1) and f(1000) == 0.05


@pytest.mark.parametrize("power", [0.5, 0.3, 1.2, math.nan])
def test_robbins_monro_condition_enforced(power: float) -> None:
    with pytest.raises(InvalidInput):
        InverseScaling(1.0, power)


def test_schedule_round_trip() -> None:
    for s in (Constant(0.2), InverseScaling(3.0, 0.6), Floor(InverseScaling(3.0, 1.0), 0.01)):
        assert schedule_from_dict(s.to_dict()) == s
    with pytest.raises(InvalidInput):
        schedule_from_dict({"kind": "inverse"})
    with pytest.raises(InvalidInput):
        schedule_from_dict({"kind": "magic", "a": 1.0})
    with pytest.raises(InvalidInput):
        schedule_from_dict({"a": 1.0, "speed": 3})


def test_default_schedule_scales_with_space() -> None:
    small = default_schedule(typical_cost=100.0, n_vehicles=4, power=1.0)
    large = default_schedule(typical_cost=1000.0, n_vehicles=4, power=1.0)
    assert isinstance(small, InverseScaling) and isinstance(large, InverseScaling)
    assert large.a == pytest.approx(10 * small.a)
    assert small.a == pytest.approx(25.0)  # half of R = 100 / sqrt(4)
    assert default_schedule(typical_cost=1000.0, n_vehicles=4, power=2.0) == InverseScaling(1, 1)
