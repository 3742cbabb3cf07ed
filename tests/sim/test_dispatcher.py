"""The dispatch rules on a deterministic fake SUMO (fast; real SUMO runs elsewhere).

The fleet service is the real in-process one on the generated grid.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from routing_svc.service.inprocess import InProcessFleetClient
from routing_svc.sim.backend import Reservation
from routing_svc.sim.dispatcher import FleetDispatcher
from routing_svc.sim.fake import FakeBackend


@pytest.fixture
def client(grid_net: Path) -> Iterator[InProcessFleetClient]:
    with InProcessFleetClient() as service:
        network = service.add_network(grid_net, name="grid")["id"]
        service.create_fleet(
            {
                "id": "f",
                "network": network,
                "cost": "time",
                "rule": "paper",  # every update moves the mover's reference
                "vehicles": [
                    {"id": "v0", "position": {"edge": "A0A1", "offset": 100.0}},
                    {"id": "v1", "position": {"edge": "F5F4", "offset": 100.0}},
                ],
            }
        )
        yield service


def _reservation(number: int, time: float, edge: str) -> Reservation:
    return Reservation(f"r{number}", f"p{number}", edge, 50.0, "C3C4", time)


def _run(backend: FakeBackend, dispatcher: FleetDispatcher, seconds: int) -> None:
    backend.start([])
    for _ in range(seconds):
        backend.step()
        dispatcher.on_step()


def test_busy_choice_falls_back_to_the_closest_idle_vehicle(client: InProcessFleetClient) -> None:
    backend = FakeBackend(
        positions={"v0": "A0A1", "v1": "F5F4"},
        reservations=[_reservation(1, 1.0, "A1A2"), _reservation(2, 2.0, "A1A2")],
    )
    dispatcher = FleetDispatcher(backend, client, "f", learn=False)
    _run(backend, dispatcher, 5)
    assert [(d.vehicle, d.reservation) for d in backend.dispatches] == [("v0", "r1"), ("v1", "r2")]
    assert dispatcher.log.chosen == {"p1": "v0", "p2": "v0"}
    assert (dispatcher.log.fallbacks, dispatcher.log.queued) == (1, 0)


def test_requests_wait_for_the_next_idle_vehicle_then_vehicles_go_home(
    client: InProcessFleetClient,
) -> None:
    reservations = [_reservation(i, float(i), "A1A2") for i in (1, 2, 3)]
    backend = FakeBackend(
        positions={"v0": "A0A1", "v1": "F5F4"}, reservations=reservations, service_seconds=100.0
    )
    dispatcher = FleetDispatcher(backend, client, "f", learn=False)
    _run(backend, dispatcher, 300)
    assert [(d.time, d.vehicle) for d in backend.dispatches] == [(1, "v0"), (2, "v1"), (101, "v0")]
    assert (dispatcher.log.queued, dispatcher.log.fallbacks) == (1, 1)
    homes = [(t, v, e) for t, v, e, _ in backend.parked]
    assert homes == [(102, "v1", "F5F4"), (201, "v0", "A0A1")]


def test_sa_updates_move_the_reference_the_vehicle_returns_to(
    client: InProcessFleetClient,
) -> None:
    backend = FakeBackend(
        positions={"v0": "A0A1", "v1": "F5F4"},
        reservations=[_reservation(1, 1.0, "A2A3")],
        service_seconds=10.0,
    )
    dispatcher = FleetDispatcher(backend, client, "f", learn=True)
    _run(backend, dispatcher, 20)
    moved = client.get_fleet("f")["vehicles"][0]["position"]
    assert (moved["edge"], moved["offset"]) != ("A0A1", 100.0)
    (_, vehicle, edge, offset) = backend.parked[0]
    assert (vehicle, edge, offset) == ("v0", moved["edge"], moved["offset"])
    assert dispatcher.references["v0"] == (moved["edge"], moved["offset"])


def test_live_travel_times_are_pushed_every_period(client: InProcessFleetClient) -> None:
    backend = FakeBackend(positions={"v0": "A0A1", "v1": "F5F4"}, reservations=[])
    free = {"A0A1": 14.4, "A1A2": 14.4}
    dispatcher = FleetDispatcher(
        backend, client, "f", learn=False, traffic_edges=free, traffic_period=30.0
    )
    _run(backend, dispatcher, 120)
    assert backend.pushes == dispatcher.log.traffic_updates == 4


def test_a_vehicle_that_leaves_the_simulation_is_counted_and_replaced(
    client: InProcessFleetClient,
) -> None:
    reservations = [_reservation(1, 1.0, "A1A2"), _reservation(2, 50.0, "A1A2")]
    backend = FakeBackend(
        positions={"v0": "A0A1", "v1": "F5F4"}, reservations=reservations, service_seconds=20.0
    )
    dispatcher = FleetDispatcher(backend, client, "f", learn=False)
    backend.start([])
    for second in range(1, 100):
        backend.step()
        if second == 10:
            backend.vanish("v0")  # while busy with r1
        dispatcher.on_step()
    assert [(d.vehicle, d.reservation) for d in backend.dispatches] == [("v0", "r1"), ("v1", "r2")]
    assert dispatcher.log.lost == ["v0"]
    assert dispatcher.log.chosen["p2"] == "v0" and dispatcher.log.fallbacks == 1
    assert [v for _, v, _, _ in backend.parked] == ["v1"]
