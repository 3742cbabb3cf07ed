"""The co-simulation drives real SUMO (libsumo) from the service's dispatch answers, on DRT.

Short horizons, no background traffic: a few persons ask for rides, the real
in-process fleet service answers, SUMO drives. The checks compare what SUMO
did (its personinfo output and taxi states) with what the service said.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from defusedxml import ElementTree

from routing_svc.network import load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.service.inprocess import InProcessFleetClient
from routing_svc.sim.backend import TAXI_GONE, TAXI_IDLE, LibsumoBackend
from routing_svc.sim.dispatcher import FleetDispatcher
from routing_svc.sim.inputs import (
    FleetVehicle,
    Request,
    passenger_lanes,
    sumo_options,
    write_fleet,
    write_persons,
    write_taxi_stands,
)
from routing_svc.sim.measures import FleetLoad, nearest_rank, service_levels


class RecordingClient(InProcessFleetClient):
    """The real in-process service, keeping every dispatch answer it gave."""

    def __init__(self) -> None:
        super().__init__()
        self.answers: list[tuple[str, str, dict[str, Any]]] = []

    def post_target(
        self, fleet_id: str, position: Mapping[str, Any], **options: Any
    ) -> dict[str, Any]:
        answer = super().post_target(fleet_id, position, **options)
        self.answers.append(("target", str(position["edge"]), answer["dispatch"]))
        return answer

    def assign(self, fleet_id: str, position: Mapping[str, Any], **options: Any) -> dict[str, Any]:
        answer = super().assign(fleet_id, position, **options)
        self.answers.append(("assign", str(position["edge"]), answer["dispatch"]))
        return answer


@pytest.fixture(scope="module")
def drt() -> Path:
    return resolve_network("drt")


def _edges(net: Path, count: int, *, seed: int) -> list[tuple[str, float]]:
    """Distinct edges of the service's network, longer than 80 m, with their lengths."""
    network = load_network(net)
    long = [i for i in range(network.n_edges) if network.length[i] > 80.0]
    picked = np.random.default_rng(seed).choice(long, size=count, replace=False)
    return [(network.edge_ids[i], float(network.length[i])) for i in picked.tolist()]


@dataclass
class Run:
    client: RecordingClient
    dispatcher: FleetDispatcher
    tripinfo: Path
    load: FleetLoad
    busy_seen: list[tuple[float, str, str]]
    """``(time, vehicle, status)`` whenever the service's status changed, seen after a step."""


def _rides(tripinfo: Path) -> dict[str, tuple[float, float, str]]:
    """Person -> (requested, SUMO wait, vehicle), read straight from SUMO's file."""
    root = ElementTree.parse(tripinfo).getroot()
    rides = {}
    for person in root.iter("personinfo"):
        ride = person.find("ride")
        assert ride is not None
        rides[str(person.get("id"))] = (
            float(person.get("depart")),
            float(ride.get("waitingTime")),
            str(ride.get("vehicle")),
        )
    return rides


@pytest.fixture
def cosim(drt: Path, tmp_path: Path) -> Iterator[Any]:
    """A function that runs the dispatcher in SUMO on DRT and checks states every step."""
    clients: list[RecordingClient] = []

    def run(
        vehicles: int,
        requests: Sequence[tuple[float, int]],
        *,
        seed: int,
        end: float,
        queue_order: str = "soonest",
    ) -> Run:
        edges = _edges(drt, vehicles + len(requests) + 1, seed=seed)
        fleet = [FleetVehicle(f"fleet{i}", e, length / 2) for i, (e, length) in enumerate(edges)]
        fleet = fleet[:vehicles]
        places = edges[vehicles:]
        persons = [
            Request(f"p{n}", t, places[k][0], 20.0, places[-1 - k][0], 20.0)
            for n, (t, k) in enumerate(requests)
        ]
        client = RecordingClient()
        clients.append(client)
        network = client.add_network(drt, name="drt")["id"]
        client.create_fleet(
            {
                "id": "f",
                "network": network,
                "cost": "time",
                "vehicles": [
                    {"id": v.id, "position": {"edge": v.edge, "offset": v.offset}} for v in fleet
                ],
            }
        )
        lengths = dict(edges)
        routes = [
            write_fleet(tmp_path / "fleet.rou.xml", fleet, lengths=lengths, park=True),
            write_persons(tmp_path / "persons.rou.xml", persons),
        ]
        tripinfo = tmp_path / "tripinfo.xml"
        backend = LibsumoBackend()
        backend.start(
            sumo_options(
                net=drt, routes=routes, end=end, seed=seed, tripinfo=tripinfo, dispatch="traci"
            )
        )
        dispatcher = FleetDispatcher(
            backend,
            client,
            "f",
            learn=True,
            edge_lengths=_network_lengths(drt),
            queue_order=queue_order,
        )
        load = FleetLoad([v.id for v in fleet], since=0.0, until=end)
        seen: dict[str, str] = {}
        changes: list[tuple[float, str, str]] = []
        try:
            while backend.time() < end:
                backend.step()
                dispatcher.on_step()
                load.sample(backend)
                for v in client.get_fleet("f")["vehicles"]:
                    vid, status = str(v["id"]), str(v["status"])
                    sumo_busy = backend.taxi_state(vid) != TAXI_IDLE
                    assert (status == "busy") == sumo_busy, (backend.time(), vid, status)
                    if seen.get(vid, "available") != status:
                        changes.append((backend.time(), vid, status))
                        if status == "available":
                            here = backend.vehicle_position(vid)
                            current = v["current"]
                            assert (current["edge"], current["offset"]) == pytest.approx(here)
                    seen[vid] = status
                finished = len(dispatcher.log.dispatched) == len(persons)
                if finished and not dispatcher.busy and not dispatcher.queue:
                    break
            dispatcher.finish()
        finally:
            backend.close()
        return Run(client, dispatcher, tripinfo, load, changes)

    yield run
    for client in clients:
        client.close()


def _network_lengths(net: Path) -> dict[str, float]:
    """The service's edges and their lengths."""
    network = load_network(net)
    return {e: float(n) for e, n in zip(network.edge_ids, network.length, strict=True)}


def test_sumo_sends_the_vehicle_the_dispatch_answer_names(cosim: Any) -> None:
    run: Run = cosim(3, [(5.0 + 30.0 * n, n) for n in range(5)], seed=11, end=2400.0)
    rides = _rides(run.tripinfo)
    assert len(rides) == 5 and all(v != "NULL" for _, _, v in rides.values())
    first_answers = [a for kind, _, a in run.client.answers if kind == "target"]
    assert len(first_answers) == 5
    for n, answer in enumerate(first_answers):
        person = f"p{n}"
        if answer["status"] == "dispatched":
            named = answer["vehicles"][0]["vehicle"]
            assert run.dispatcher.log.named[person] == named
        # whoever SUMO's personinfo says picked the person up is the vehicle the service named
        assert rides[person][2] == run.dispatcher.log.named[person]
    assert run.dispatcher.log.failed == 0
    # the service saw each vehicle go busy at a dispatch and available after the drop-off
    for vehicle in {v for _, v, _ in run.busy_seen}:
        statuses = [s for _, v, s in run.busy_seen if v == vehicle]
        assert statuses[0] == "busy" and statuses[-1] == "available"
        assert all(a != b for a, b in itertools.pairwise(statuses))
    assert run.dispatcher.log.state_batches > 0


def test_queued_requests_are_served_in_fifo_order(cosim: Any) -> None:
    requests = [(10.0, 0), (11.0, 1), (12.0, 2), (13.0, 3)]
    run: Run = cosim(1, requests, seed=5, end=4000.0, queue_order="fifo")
    kinds = [(kind, answer["status"]) for kind, _, answer in run.client.answers]
    assert kinds[:4] == [("target", "dispatched")] + [("target", "queued")] * 3
    assert run.dispatcher.log.queued == 3
    assert run.dispatcher.log.from_queue == ["p1", "p2", "p3"]
    rides = _rides(run.tripinfo)
    picked_up = [rides[f"p{n}"][0] + rides[f"p{n}"][1] for n in range(4)]
    assert picked_up == sorted(picked_up) and len(set(picked_up)) == 4
    assert {v for _, _, v in rides.values()} == {"fleet0"}
    sent = [s for _, _, s in run.dispatcher.log.state_changes]
    collapsed = [s for n, s in enumerate(sent) if n == 0 or sent[n - 1] != s]
    assert collapsed == ["busy", "available"] * 4


def test_a_freed_vehicle_takes_the_waiting_request_the_service_prices_soonest(
    cosim: Any,
) -> None:
    requests = [(10.0 + n, n) for n in range(5)]
    run: Run = cosim(1, requests, seed=5, end=6000.0)
    targets = [(edge, answer) for kind, edge, answer in run.client.answers if kind == "target"]
    edge_of = {f"p{n}": edge for n, (edge, _) in enumerate(targets)}
    assert [a["status"] for _, a in targets] == ["dispatched"] + ["queued"] * 4
    # each drop-off asks the service about every waiting request (a round), and sends
    # the vehicle to the one it names the least cost for
    rounds: list[list[tuple[str, float]]] = [[]]
    for kind, edge, answer in run.client.answers:
        if kind == "assign" and answer["status"] == "dispatched":
            rounds[-1].append((edge, float(answer["vehicles"][0]["cost"])))
        elif rounds[-1]:
            rounds.append([])
    rounds = [r for r in rounds if r]
    chosen = [min(r, key=lambda priced: priced[1])[0] for r in rounds]
    assert chosen == [edge_of[p] for p in run.dispatcher.log.from_queue]
    assert sorted(run.dispatcher.log.from_queue) == ["p1", "p2", "p3", "p4"]
    assert run.dispatcher.log.from_queue != ["p1", "p2", "p3", "p4"]  # not the FIFO order
    assert max(len(r) for r in rounds) == 4
    rides = _rides(run.tripinfo)
    assert {v for _, _, v in rides.values()} == {"fleet0"} and len(rides) == 5


def test_metrics_of_a_small_recorded_run_by_hand(cosim: Any) -> None:
    run: Run = cosim(2, [(10.0, 0), (12.0, 1), (14.0, 2), (200.0, 3)], seed=7, end=3000.0)
    rides = _rides(run.tripinfo)
    waits = sorted(w for _, w, _ in rides.values())
    levels = service_levels(
        [(t, w, v != "NULL") for t, w, v in rides.values()], since=0.0, thresholds=(60.0, 300.0)
    )
    # nearest rank of 4 waits: p50 is the 2nd smallest, p90 and p95 the largest
    assert (levels["p50_wait_s"], levels["p90_wait_s"]) == (waits[1], waits[3])
    assert levels["within"] == {
        "60": sum(w <= 60.0 for w in waits) / 4,
        "300": sum(w <= 300.0 for w in waits) / 4,
    }
    # busy fraction: the sampled SUMO taxi states against the busy intervals the
    # service was told about, within one 10 s sample per state change
    busy_since: dict[str, float] = {}
    busy_seconds = 0.0
    for time, vehicle, status in run.busy_seen:
        if status == "busy":
            busy_since[vehicle] = time
        else:
            busy_seconds += time - busy_since.pop(vehicle)
    horizon = run.load.samples / 2 * run.load.period
    assert run.load.busy_fraction == pytest.approx(
        busy_seconds / (2 * horizon), abs=len(run.busy_seen) * run.load.period / (2 * horizon)
    )


def test_nearest_rank_and_service_levels_by_hand() -> None:
    assert nearest_rank([5.0, 1.0, 3.0], 50.0) == 3.0  # ceil(1.5) = 2nd smallest
    assert nearest_rank([5.0, 1.0, 3.0], 90.0) == 5.0
    assert math.isnan(nearest_rank([], 90.0))
    waits = [(0.0, 30.0, True), (10.0, 50.0, True), (20.0, 400.0, True), (30.0, 700.0, True)]
    waits += [(40.0, 0.0, False), (-5.0, 1.0, True)]  # never served; before the period
    levels = service_levels(waits, since=0.0)
    assert levels["p50_wait_s"] == 400.0  # [30, 50, 400, 700, inf]: 3rd
    assert levels["p90_wait_s"] == math.inf
    assert levels["within"] == {"300": 2 / 5, "600": 3 / 5, "900": 4 / 5}


def test_sumo_taxistand_sends_idle_taxis_to_the_stands(drt: Path, tmp_path: Path) -> None:
    edges = _edges(drt, 6, seed=3)
    lengths = dict(edges)
    sites = [FleetVehicle(f"fleet{i}", e, length / 2) for i, (e, length) in enumerate(edges[:2])]
    stands = write_taxi_stands(
        tmp_path / "stands.add.xml",
        sites,
        lengths=lengths,
        lanes=passenger_lanes(drt, [s.edge for s in sites]),
        capacity=2,
    )
    fleet = write_fleet(tmp_path / "fleet.rou.xml", sites, lengths=lengths, park=False, stands=True)
    persons = write_persons(
        tmp_path / "persons.rou.xml",
        [  # the second keeps the taxis in the simulation (they leave when nobody is left)
            Request("p0", 30.0, edges[2][0], 20.0, edges[3][0], 20.0),
            Request("p1", 1400.0, edges[4][0], 20.0, edges[5][0], 20.0),
        ],
    )
    backend = LibsumoBackend()
    backend.start(
        sumo_options(
            net=drt,
            routes=[fleet, persons],
            end=1500.0,
            seed=0,
            tripinfo=tmp_path / "tripinfo.xml",
            dispatch="greedy",
            idle="taxistand",
            additional=[stands],
        )
    )
    try:
        served = False
        while backend.time() < 1500.0:
            backend.step()
            states = [backend.taxi_state(s.id) for s in sites]
            assert TAXI_GONE not in states
            served = served or any(s > TAXI_IDLE for s in states)
            if served and all(s == TAXI_IDLE for s in states) and backend.time() > 600.0:
                break
        for _ in range(300):  # time to drive back to a stand
            backend.step()
        places = {backend.vehicle_position(s.id)[0] for s in sites}
        assert served and places <= {s.edge for s in sites}
    finally:
        backend.close()
