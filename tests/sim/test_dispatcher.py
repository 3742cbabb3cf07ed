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


def _statuses(client: InProcessFleetClient) -> dict[str, str]:
    return {str(v["id"]): str(v["status"]) for v in client.get_fleet("f")["vehicles"]}


def test_the_service_names_the_available_vehicle_and_sees_it_busy(
    client: InProcessFleetClient,
) -> None:
    backend = FakeBackend(
        positions={"v0": "A0A1", "v1": "F5F4"},
        reservations=[_reservation(1, 1.0, "A1A2"), _reservation(2, 2.0, "A1A2")],
    )
    dispatcher = FleetDispatcher(backend, client, "f", learn=False)
    _run(backend, dispatcher, 5)
    # v0 is closest to both; busy with p1, so the service names v1 for p2
    assert [(d.vehicle, d.reservation) for d in backend.dispatches] == [("v0", "r1"), ("v1", "r2")]
    assert dispatcher.log.named == dispatcher.log.dispatched == {"p1": "v0", "p2": "v1"}
    assert _statuses(client) == {"v0": "busy", "v1": "busy"}
    assert dispatcher.log.queued == 0


def test_queued_requests_are_served_first_in_order_then_vehicles_go_home(
    client: InProcessFleetClient,
) -> None:
    reservations = [_reservation(i, float(i), "A1A2") for i in (1, 2, 3, 4)]
    backend = FakeBackend(
        positions={"v0": "A0A1", "v1": "F5F4"}, reservations=reservations, service_seconds=100.0
    )
    dispatcher = FleetDispatcher(backend, client, "f", learn=False)
    _run(backend, dispatcher, 400)
    sent = [(d.time, d.vehicle, d.reservation) for d in backend.dispatches]
    assert sent == [(1, "v0", "r1"), (2, "v1", "r2"), (101, "v0", "r3"), (102, "v1", "r4")]
    assert dispatcher.log.queued == 2 and dispatcher.log.from_queue == ["p3", "p4"]
    homes = [(t, v, e) for t, v, e, _ in backend.parked]
    assert homes == [(201, "v0", "A0A1"), (202, "v1", "F5F4")]
    assert _statuses(client) == {"v0": "available", "v1": "available"}
    assert ("v0", "busy") in [(v, s) for _, v, s in dispatcher.log.state_changes]


@pytest.mark.parametrize(
    ("queue_order", "overdue_after", "served"),
    [
        # v0, free at C3C4 at 101, takes r4 next door although r3 came first
        ("soonest", 900.0, [(101, "v0", "r4"), (102, "v1", "r3")]),
        # r3 has waited 98 s at 101: past a limit of 90 s it goes first
        ("soonest", 90.0, [(101, "v0", "r3"), (102, "v1", "r4")]),
        ("fifo", 900.0, [(101, "v0", "r3"), (102, "v1", "r4")]),
    ],
)
def test_a_freed_vehicle_serves_the_waiting_request_the_queue_order_names(
    client: InProcessFleetClient,
    queue_order: str,
    overdue_after: float,
    served: list[tuple[float, str, str]],
) -> None:
    # both vehicles busy until 101 and 102, then idle at C3C4 (the fake's drop-off);
    # r3 waits at A0A1, far from C3C4, r4 at C4C5, which starts where C3C4 ends
    reservations = [
        _reservation(1, 1.0, "A1A2"),
        _reservation(2, 2.0, "A1A2"),
        _reservation(3, 3.0, "A0A1"),
        _reservation(4, 4.0, "C4C5"),
    ]
    backend = FakeBackend(
        positions={"v0": "A0A1", "v1": "F5F4"}, reservations=reservations, service_seconds=100.0
    )
    dispatcher = FleetDispatcher(
        backend, client, "f", learn=False, queue_order=queue_order, overdue_after=overdue_after
    )
    _run(backend, dispatcher, 150)
    sent = [(d.time, d.vehicle, d.reservation) for d in backend.dispatches]
    assert sent == [(1, "v0", "r1"), (2, "v1", "r2"), *served]
    assert dispatcher.log.queued == 2 and not dispatcher.queue
    assert dispatcher.log.from_queue == [f"p{r[-1]}" for _, _, r in served]


def test_an_unknown_queue_order_is_refused(client: InProcessFleetClient) -> None:
    backend = FakeBackend(positions={"v0": "A0A1", "v1": "F5F4"}, reservations=[])
    with pytest.raises(ValueError, match="queue_order"):
        FleetDispatcher(backend, client, "f", learn=False, queue_order="random")


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


def test_a_vehicle_that_leaves_the_simulation_is_reported_offline(
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
    sent = [(d.time, d.vehicle, d.reservation) for d in backend.dispatches]
    # r1's carrier left before the drop-off: r1 is asked for again and v1 serves it
    assert sent == [(1, "v0", "r1"), (10, "v1", "r1"), (50, "v1", "r2")]
    assert dispatcher.log.lost == ["v0"] and dispatcher.log.orphaned == ["p1"]
    assert _statuses(client) == {"v0": "offline", "v1": "available"}
    assert [v for _, v, _, _ in backend.parked] == ["v1", "v1"]


@pytest.mark.parametrize("move_up", [True, False])
def test_with_move_up_a_free_vehicle_holds_a_busy_ones_reference_until_it_is_back(
    grid_net: Path, move_up: bool
) -> None:
    starts = {"v0": "A1A2", "v1": "B1B2", "v2": "F5F4"}
    with InProcessFleetClient() as client:
        network = client.add_network(grid_net, name="grid")["id"]
        vehicles = [{"id": v, "position": {"edge": e, "offset": 100.0}} for v, e in starts.items()]
        client.create_fleet(
            {"id": "f", "network": network, "cost": "time", "rule": "paper", "vehicles": vehicles}
        )
        backend = FakeBackend(
            positions=starts, reservations=[_reservation(1, 1.0, "F4F5")], service_seconds=100.0
        )
        dispatcher = FleetDispatcher(backend, client, "f", learn=False, move_up=move_up)
        _run(backend, dispatcher, 50)
        assert [d.vehicle for d in backend.dispatches] == ["v2"]
        covering = [(v, e) for _, v, e, _ in backend.parked if v != "v2"]
        if not move_up:
            assert covering == []
            return
        # v0 and v1 wait side by side: the far reference of v2 is the better second post
        posts = {p["vehicle"]: p for p in client.posts("f")["posts"]}
        assert set(posts) == {"v0", "v1"} and {p["reference_of"] for p in posts.values()} != {
            "v0",
            "v1",
        }
        (mover,) = [v for v, p in posts.items() if p["reference_of"] == "v2"]
        assert covering == [(mover, "F5F4")]
        assert dispatcher.posts[mover] == ("F5F4", 100.0)
        _run_more(backend, dispatcher, 100)  # v2 is free again, at the drop-off (C3C4)
        # every reference is held again; v2 takes over the reference its cover left,
        # which costs less driving than both going back
        last = {v: (e, o) for _, v, e, o in backend.parked}
        assert last == {mover: ("F5F4", 100.0), "v2": (starts[mover], 100.0)}
        held = {p["vehicle"]: p["reference_of"] for p in client.posts("f")["posts"]}
        assert held == {
            mover: "v2",
            "v2": mover,
            ({"v0", "v1"} - {mover}).pop(): ({"v0", "v1"} - {mover}).pop(),
        }


def _run_more(backend: FakeBackend, dispatcher: FleetDispatcher, seconds: int) -> None:
    for _ in range(seconds):
        backend.step()
        dispatcher.on_step()
