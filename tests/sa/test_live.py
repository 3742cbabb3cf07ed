"""Dispatch and the availability-aware rule on the plane, against brute force and by hand."""

from __future__ import annotations

import math

import pytest

from routing_svc.errors import Conflict, NotFound
from routing_svc.sa import (
    ROUTING,
    Constant,
    EuclideanPlane,
    Fleet,
    FleetConfig,
    LearningVehicles,
    Status,
    Vehicle,
    VehicleState,
)
from routing_svc.types import PlanePosition as Pt

BUSY: VehicleState[Pt] = VehicleState(Status.BUSY)


def make_fleet(
    points: list[tuple[str, str, Pt]], learning: LearningVehicles = LearningVehicles.ALL
) -> Fleet[Pt]:
    config = FleetConfig(objective=ROUTING, schedule=Constant(1.0), learning_vehicles=learning)
    vehicles = [(Vehicle(vid, kind), p) for vid, kind, p in points]
    return Fleet.create(EuclideanPlane(side=10.0), vehicles, config)


def test_dispatch_and_learning_by_hand() -> None:
    points = [("a", "A", Pt(0.0, 0.0)), ("b", "A", Pt(6.0, 0.0)), ("c", "B", Pt(0.0, 9.0))]
    for learning, mover in ((LearningVehicles.ALL, "a"), (LearningVehicles.AVAILABLE, "b")):
        fleet = make_fleet(points, learning)
        # a is busy; b waits at (6, 0) but is now at (1, 1)
        fleet.set_states([("a", BUSY), ("b", VehicleState(Status.AVAILABLE, Pt(1.0, 1.0)))])
        out = fleet.observe(Pt(2.0, 1.0))
        assert out.dispatch.sent is not None
        assert out.dispatch.sent.vehicles == ("b",) and out.dispatch.sent.times == (1.0,)
        assert out.dispatch.moved == mover
        # b moved by one (the schedule's gamma) from its reference, not from where it is
        if mover == "b":
            norm = math.hypot(4.0, 1.0)
            assert out.new_position == pytest.approx(Pt(6.0 - 4.0 / norm, 1.0 / norm))
        both = fleet.assign(Pt(0.0, 1.0), ["A", "B"])
        assert both.sent is not None
        assert both.sent.vehicles == ("b", "c") and both.sent.types == ("A", "B")
        assert both.sent.times == (1.0, 8.0) and both.sent.completion == 8.0


def test_queued_partial_and_bad_changes() -> None:
    fleet = make_fleet([("a", "A", Pt(0.0, 0.0)), ("c", "B", Pt(0.0, 9.0))])
    fleet.set_states([("a", BUSY)])
    partial = fleet.assign(Pt(1.0, 0.0), ["A", "B"]).sent
    assert partial is not None and (partial.status, partial.missing) == ("partial", ("A",))
    fleet.set_states([("c", VehicleState(Status.OFFLINE))])
    queued = fleet.assign(Pt(1.0, 0.0)).sent
    assert queued is not None and (queued.status, queued.vehicles) == ("queued", ())
    before = list(fleet.state.vehicle_states)
    with pytest.raises(NotFound):
        fleet.set_states([("a", VehicleState(Status.AVAILABLE)), ("zz", BUSY)])
    fleet.set_states([("a", VehicleState(Status.BUSY, None, 10.0))])
    with pytest.raises(Conflict):
        fleet.set_states(
            [("c", VehicleState(Status.AVAILABLE)), ("a", VehicleState(Status.BUSY, None, 9.0))]
        )
    assert fleet.state.vehicle_states[1] == before[1]
