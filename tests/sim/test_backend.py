"""The libsumo backend on its own: reservations, dispatch, parking at a reference."""

from __future__ import annotations

from pathlib import Path

import pytest

from routing_svc.network.catalogue import resolve_network
from routing_svc.sim.backend import (
    TAXI_GONE,
    LibsumoBackend,
    Reservation,
    SimBackend,
    SimulationError,
    make_backend,
)
from routing_svc.sim.inputs import (
    FleetVehicle,
    Request,
    sumo_options,
    write_fleet,
    write_persons,
    write_taxi_stands,
)

GRID_VEHICLE = FleetVehicle("fleet000", "B2C2", 100.0)
"""The fleet vehicle of these tests on the grid."""


def _start(
    grid_net: Path,
    tmp_path: Path,
    *,
    requests: list[Request],
    kind: str = "libsumo",
    additional: tuple[Path, ...] = (),
    vehicle: FleetVehicle = GRID_VEHICLE,
    length: float = 200.0,
    park: bool = True,
) -> SimBackend:
    """SUMO on ``grid_net`` (or another network) with one fleet vehicle on an edge of
    ``length`` metres, parked at the start unless ``park`` is false, and the persons of
    ``requests``."""
    fleet = write_fleet(
        tmp_path / "fleet.rou.xml",
        [vehicle],
        lengths={vehicle.edge: length},
        park=park,
    )
    persons = write_persons(tmp_path / "persons.rou.xml", requests)
    backend = make_backend(kind)
    backend.start(
        sumo_options(
            net=grid_net,
            routes=[fleet, persons],
            end=1200,
            seed=0,
            tripinfo=tmp_path / "tripinfo.xml",
            dispatch="traci",
            additional=additional,
        )
    )
    return backend


@pytest.mark.parametrize("kind", ["libsumo", "traci"])
def test_reservation_dispatch_and_return_to_the_reference(
    grid_net: Path, tmp_path: Path, kind: str
) -> None:
    request = Request("p0", 10.0, "D3D4", 50.0, "E4E5", 100.0)
    backend = _start(grid_net, tmp_path, requests=[request], kind=kind)
    try:
        found: list[Reservation] = []
        while not found:
            backend.step()
            found = backend.new_reservations()
        (reservation,) = found
        assert (reservation.person, reservation.from_edge) == ("p0", "D3D4")
        assert reservation.from_pos == pytest.approx(50.0)
        assert backend.taxi_state("fleet000") == 0
        assert 0.0 < backend.route_time("B2C2", "D3D4", "fleet") < 600.0
        backend.dispatch("fleet000", reservation.id)
        assert backend.taxi_state("fleet000") != 0
        while backend.taxi_state("fleet000") != 0:
            backend.step()
        backend.park_at("fleet000", "B2C2", 100.0)
        for _ in range(400):
            backend.step()
        assert backend.current_edge("fleet000") == "B2C2"
        assert backend.lane_position("fleet000") == pytest.approx(100.0, abs=1.0)
    finally:
        backend.close()


def test_parking_behind_the_vehicle_on_its_own_edge_drives_a_loop(
    grid_net: Path, tmp_path: Path
) -> None:
    backend = _start(grid_net, tmp_path, requests=[])
    try:
        backend.step()
        backend.park_at("fleet000", "B2C2", 20.0)  # behind: it has to come around
        seen = set()
        for _ in range(600):
            backend.step()
            seen.add(backend.current_edge("fleet000"))
        assert len(seen) >= 2  # it left the edge (a U-turn at C2 is allowed) and came back
        assert backend.current_edge("fleet000") == "B2C2"
        assert backend.lane_position("fleet000") == pytest.approx(20.0, abs=1.0)
    finally:
        backend.close()


def _parked_near(backend: SimBackend, vehicle: str, edge: str, offset: float) -> bool:
    here, position = backend.vehicle_position(vehicle)
    return here == edge and abs(position - offset) <= 1.0


@pytest.mark.parametrize("kind", ["libsumo", "traci"])
def test_a_vehicle_sent_where_it_is_parked_stays_parked(
    grid_net: Path, tmp_path: Path, kind: str
) -> None:
    # SUMO would take the new stop for the current one, end it on resume, and the
    # vehicle would drive to the end of its route and leave the simulation
    stands = write_taxi_stands(
        tmp_path / "stands.add.xml",
        [FleetVehicle("stand", "C2D2", 100.0)],
        lengths={"C2D2": 200.0},
        lanes={},
        capacity=2,
    )
    backend = _start(grid_net, tmp_path, requests=[], kind=kind, additional=(stands,))
    try:
        for _ in range(30):
            backend.step()
        assert _parked_near(backend, "fleet000", "B2C2", 100.0)
        backend.park_at("fleet000", "B2C2", 100.0)  # where it was parked from the start
        for _ in range(600):
            backend.step()
        assert backend.taxi_state("fleet000") != TAXI_GONE
        assert _parked_near(backend, "fleet000", "B2C2", 100.0)
        (area,) = backend.api.parkingarea.getIDList()  # type: ignore[attr-defined]
        backend.park_in("fleet000", area)
        for _ in range(600):
            backend.step()
        assert backend.parked_in(area) == ["fleet000"]
        backend.park_in("fleet000", area)
        for _ in range(600):
            backend.step()
        assert backend.taxi_state("fleet000") != TAXI_GONE
        assert backend.parked_in(area) == ["fleet000"]
    finally:
        backend.close()


@pytest.mark.parametrize("kind", ["libsumo", "traci"])
@pytest.mark.parametrize("behind", [0.01, 1.0])
def test_a_parked_taxi_picks_up_a_customer_just_behind_it(
    tmp_path: Path, kind: str, behind: float
) -> None:
    # On this edge of bs3d SUMO drops a pickup 1 cm behind the taxi's parking stop and
    # keeps the drop-off: the taxi would drive off without its customer. 1 m behind, it
    # takes the pickup and drives round the block.
    edge, parked = "-33049407#2", 20.0
    request = Request("p0", 400.0, edge, parked - behind, "108892340#1", 30.0)
    backend = _start(
        resolve_network("bs3d"),
        tmp_path,
        requests=[request],
        kind=kind,
        vehicle=FleetVehicle("fleet000", "33049438#0", 10.0),
        length=114.96,
        park=False,
    )
    try:
        backend.step()
        backend.park_at("fleet000", edge, parked)
        found: list[Reservation] = []
        while not found:
            backend.step()
            found = backend.new_reservations()
        assert _parked_near(backend, "fleet000", edge, parked)
        backend.dispatch("fleet000", found[0].id)
        carried = False
        for _ in range(600):
            backend.step()
            carried = carried or "p0" in backend.api.vehicle.getPersonIDList("fleet000")  # type: ignore[attr-defined]
        assert carried
        assert backend.taxi_state("fleet000") == 0  # delivered, idle, still in the simulation
        assert "p0" not in backend.api.person.getIDList()  # type: ignore[attr-defined]
    finally:
        backend.close()


def test_places_of_vehicles_and_travel_times(grid_net: Path, tmp_path: Path) -> None:
    backend = _start(grid_net, tmp_path, requests=[])
    try:
        backend.step()
        places = backend.vehicle_places()
        assert [p[0] for p in places] == ["fleet000"]
        assert places[0][1] == "B2C2"
        (seconds,) = backend.edge_travel_times(["B2C2"])
        assert seconds > 0.0
    finally:
        backend.close()


def test_unknown_backend_and_unstarted_simulation() -> None:
    with pytest.raises(SimulationError):
        make_backend("carla")
    with pytest.raises(SimulationError, match="not been started"):
        LibsumoBackend().step()


@pytest.mark.parametrize("kind", ["libsumo", "traci"])
def test_a_vehicle_waiting_to_be_inserted_is_at_the_start_of_its_first_edge(
    grid_net: Path, tmp_path: Path, kind: str
) -> None:
    """Three vehicles inserted at the same place: SUMO holds back those that do not fit,
    and where they are is where they will enter (their route index is negative)."""
    fleet = write_fleet(
        tmp_path / "fleet.rou.xml",
        [FleetVehicle(f"fleet00{i}", "B2C2", 100.0) for i in range(3)],
        lengths={"B2C2": 200.0},
        park=False,
    )
    backend = make_backend(kind)
    backend.start(
        sumo_options(
            net=grid_net,
            routes=[fleet],
            end=60,
            seed=0,
            tripinfo=tmp_path / "tripinfo.xml",
            dispatch="traci",
        )
    )
    try:
        backend.step()
        inserted = {p[0] for p in backend.vehicle_places()}
        waiting = sorted({"fleet000", "fleet001", "fleet002"} - inserted)
        assert waiting, "every vehicle was inserted at once"
        for vehicle in waiting:
            assert backend.current_edge(vehicle) == "B2C2"
            assert backend.vehicle_position(vehicle) == ("B2C2", 0.0)
    finally:
        backend.close()
