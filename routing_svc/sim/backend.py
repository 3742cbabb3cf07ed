"""The seam between the co-simulation and a running SUMO: :class:`SimBackend`.

The co-simulation never imports ``libsumo`` or ``traci`` itself; it talks to a
backend, as httpx talks to a transport:

- :class:`LibsumoBackend` runs SUMO inside this process through ``libsumo``
  (fast; imported lazily in :meth:`LibsumoBackend.start`). libsumo allows one
  simulation per process, so seeds run in parallel as processes.
- :class:`TraciBackend` runs ``sumo`` or ``sumo-gui`` as a child process and
  talks TraCI over a socket (slower; for a GUI, or several simulations in one
  process).

Both offer the same small set of operations that the dispatcher, the
incident sampler and the traffic probe need. The libsumo and traci Python APIs
are identical, so both backends share :class:`_ApiBackend`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from routing_svc.errors import RoutingSvcError

__all__ = [
    "LibsumoBackend",
    "Reservation",
    "SimBackend",
    "SimulationError",
    "TraciBackend",
    "make_backend",
]

#: ``device.taxi.state`` of an idle taxi (no customer assigned or on board).
TAXI_IDLE = 0

#: :meth:`SimBackend.taxi_state` of a vehicle that is no longer in the simulation.
TAXI_GONE = -1

#: Duration of the stop that parks a fleet vehicle at its reference position.
PARK_SECONDS = 1e7

#: Deceleration (m/s^2) assumed to decide whether a stop ahead can still be reached.
BRAKING = 4.5

#: A vehicle parked within this distance (m) of the place it is sent to is already there.
PARKED_TOLERANCE = 1.0


class SimulationError(RoutingSvcError):
    """SUMO refused an operation or could not start."""

    title = "Simulation error"


@dataclass(frozen=True, slots=True)
class Reservation:
    """A taxi reservation as SUMO reports it (a person waiting for a ride)."""

    id: str
    person: str
    from_edge: str
    from_pos: float
    to_edge: str
    time: float
    """When the reservation was made (simulated seconds)."""


class SimBackend(Protocol):
    """What the co-simulation asks of a running SUMO."""

    def start(self, args: Sequence[str]) -> None:
        """Start SUMO with command-line ``args`` (without the binary)."""
        ...

    def step(self) -> None:
        """Advance one simulation step."""
        ...

    def time(self) -> float:
        """Current simulated time in seconds."""
        ...

    def close(self) -> None:
        """End the simulation and flush SUMO's output files."""
        ...

    def new_reservations(self) -> list[Reservation]:
        """Taxi reservations made since the last call, oldest first."""
        ...

    def dispatch(self, vehicle: str, reservation: str) -> None:
        """Send taxi ``vehicle`` to serve ``reservation``.

        Raises ``SimulationError`` when SUMO refuses, or accepts without the pickup.
        """
        ...

    def taxi_state(self, vehicle: str) -> int:
        """``device.taxi.state``: 0 idle, 1 driving to a pick-up, 2/3 with a customer;
        :data:`TAXI_GONE` if the vehicle has left the simulation."""
        ...

    def current_edge(self, vehicle: str) -> str:
        """The (non-internal) edge a vehicle is on or enters next (the first of its route
        while it waits to be inserted)."""
        ...

    def lane_position(self, vehicle: str) -> float:
        """Distance driven along the vehicle's current lane."""
        ...

    def vehicle_position(self, vehicle: str) -> tuple[str, float]:
        """``(edge, offset)`` of a vehicle: on a junction, or while it waits to be inserted,
        the start of the edge it enters next."""
        ...

    def route_time(self, from_edge: str, to_edge: str, vtype: str) -> float:
        """SUMO's current travel time of the fastest route between two edges (inf if none)."""
        ...

    def park_at(self, vehicle: str, edge: str, offset: float) -> None:
        """Drive ``vehicle`` to ``(edge, offset)`` and park there until dispatched;
        nothing if it is parked there already.

        Raises ``SimulationError`` when SUMO cannot do it now (e.g. the vehicle
        is on a junction); the caller tries again a step later.
        """
        ...

    def park_in(self, vehicle: str, area: str) -> None:
        """Drive ``vehicle`` to SUMO parkingArea ``area`` and park in it until dispatched;
        nothing if it is parked in it already.

        Raises ``SimulationError`` as :meth:`park_at` does.
        """
        ...

    def parked_in(self, area: str) -> list[str]:
        """The vehicles parked in SUMO parkingArea ``area`` now, by id."""
        ...

    def vehicle_places(self) -> list[tuple[str, str, float]]:
        """``(vehicle, edge, lane position)`` of the vehicles on normal edges, by id."""
        ...

    def edge_travel_times(self, edges: Sequence[str]) -> list[float]:
        """SUMO's current travel time (length / mean speed) of each edge."""
        ...


class _ApiBackend:
    """The operations on top of a libsumo module or a traci connection (same API)."""

    def __init__(self) -> None:
        self._api: Any = None
        self._error: type[Exception] = Exception
        self._lanes: dict[str, int] = {}

    @property
    def api(self) -> Any:
        if self._api is None:
            raise SimulationError("the simulation has not been started")
        return self._api

    def start(self, args: Sequence[str]) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def step(self) -> None:
        self.api.simulationStep()

    def time(self) -> float:
        return float(self.api.simulation.getTime())

    def new_reservations(self) -> list[Reservation]:
        found = [
            Reservation(
                id=str(r.id),
                person=str(r.persons[0]),
                from_edge=str(r.fromEdge),
                from_pos=float(r.departPos),
                to_edge=str(r.toEdge),
                time=float(r.reservationTime),
            )
            for r in self.api.person.getTaxiReservations(1)
        ]
        return sorted(found, key=lambda r: (r.time, r.person))

    def dispatch(self, vehicle: str, reservation: str) -> None:
        vehicle_api = self.api.vehicle
        try:
            vehicle_api.dispatchTaxi(vehicle, [reservation])
            if not self._picks_up(vehicle, reservation) and vehicle_api.isStopped(vehicle):
                # SUMO drops a pickup a hair behind the stop the taxi is making and keeps
                # the drop-off (the taxi would leave without its customer); once that
                # stop has ended, it takes the pickup
                vehicle_api.resume(vehicle)
                vehicle_api.dispatchTaxi(vehicle, [reservation])
        except self._error as exc:
            raise SimulationError(f"dispatch of {vehicle} to {reservation}: {exc}") from None
        if not self._picks_up(vehicle, reservation):
            raise SimulationError(f"SUMO sent {vehicle} for {reservation} without its pickup")

    def _picks_up(self, vehicle: str, reservation: str) -> bool:
        """Whether one of ``vehicle``'s stops ahead picks up the customer of ``reservation``
        (SUMO's ``actType`` ``"pickup <person> (<reservation>)"``)."""
        acts = [str(stop.actType) for stop in self.api.vehicle.getStops(vehicle)]
        return any(a.startswith("pickup") and a.endswith(f"({reservation})") for a in acts)

    def taxi_state(self, vehicle: str) -> int:
        try:
            return int(self.api.vehicle.getParameter(vehicle, "device.taxi.state"))
        except self._error:
            if vehicle not in self.api.vehicle.getIDList():
                return TAXI_GONE
            raise

    def current_edge(self, vehicle: str) -> str:
        road = str(self.api.vehicle.getRoadID(vehicle))
        if road and not road.startswith(":"):
            return road
        route = self.api.vehicle.getRoute(vehicle)
        # negative while the vehicle waits to be inserted: it enters its first edge next
        index = max(int(self.api.vehicle.getRouteIndex(vehicle)), -1)
        return str(route[min(index + 1, len(route) - 1)])

    def lane_position(self, vehicle: str) -> float:
        return float(self.api.vehicle.getLanePosition(vehicle))

    def vehicle_position(self, vehicle: str) -> tuple[str, float]:
        road = str(self.api.vehicle.getRoadID(vehicle))
        if road and not road.startswith(":"):
            return road, self.lane_position(vehicle)
        return self.current_edge(vehicle), 0.0

    def route_time(self, from_edge: str, to_edge: str, vtype: str) -> float:
        try:
            route = self.api.simulation.findRoute(from_edge, to_edge, vType=vtype)
        except self._error:
            return math.inf
        return float(route.travelTime) if route.edges else math.inf

    def park_at(self, vehicle: str, edge: str, offset: float) -> None:
        current = self._parked(vehicle)
        if (
            current is not None
            and current.lane.rpartition("_")[0] == edge
            and abs(float(current.endPos) - offset) <= PARKED_TOLERANCE
        ):
            return

        def stop() -> None:
            self.api.vehicle.setStop(
                vehicle,
                edge,
                pos=offset,
                laneIndex=self._stop_lane(edge),
                duration=PARK_SECONDS,
                flags=1,
            )

        self._park(vehicle, edge, offset, stop, f"{edge}@{offset:.1f}")

    def park_in(self, vehicle: str, area: str) -> None:
        current = self._parked(vehicle)
        if current is not None and current.stoppingPlaceID == area:
            return
        try:
            lane = str(self.api.parkingarea.getLaneID(area))
            start = float(self.api.parkingarea.getStartPos(area))
        except self._error as exc:
            raise SimulationError(f"no parkingArea {area!r}: {exc}") from None
        edge = lane.rpartition("_")[0] or lane

        def stop() -> None:
            self.api.vehicle.setParkingAreaStop(vehicle, area, PARK_SECONDS)

        self._park(vehicle, edge, start, stop, f"parkingArea {area}")

    def _parked(self, vehicle: str) -> Any:
        """The parking stop (of :data:`PARK_SECONDS`) ``vehicle`` is making now, as SUMO's
        stop data, or ``None`` (it drives, or makes another stop such as a drop-off).

        Parking it again where it stands would not be a no-op: the new stop would
        replace the current one, which ``resume`` then ends, and the vehicle would
        drive off to the end of its route and leave the simulation.
        """
        vehicle_api = self.api.vehicle
        if not vehicle_api.isStopped(vehicle):
            return None
        stops = vehicle_api.getStops(vehicle, 1)
        # SUMO reports the duration left; no other stop lasts half as long
        return stops[0] if stops and float(stops[0].duration) > PARK_SECONDS / 2 else None

    def _park(self, vehicle: str, edge: str, offset: float, stop: Any, where: str) -> None:
        """Route ``vehicle`` to ``(edge, offset)`` and add the parking ``stop`` there."""
        vehicle_api = self.api.vehicle
        road = str(vehicle_api.getRoadID(vehicle))
        if not road or road.startswith(":"):
            raise SimulationError(f"{vehicle} is crossing a junction; send it home later")
        stopped = bool(vehicle_api.isStopped(vehicle))
        try:
            # Plan the new route before the vehicle gives up its current stops (e.g.
            # the drop-off, or the way to a former home): if SUMO finds none, nothing
            # has changed and the vehicle does not drive off the end of its old route.
            speed = float(vehicle_api.getSpeed(vehicle))
            braking = speed * speed / (2.0 * BRAKING) + 1.0
            ahead = road == edge and self.lane_position(vehicle) + braking < offset
            vtype = str(vehicle_api.getTypeID(vehicle))
            loop = self._loop(road, edge, vtype) if road == edge and not ahead else None
            if loop is None and not math.isfinite(self.route_time(road, edge, vtype)):
                raise SimulationError(f"no route for {vehicle} from {road} to {where}")
            pending = len(vehicle_api.getStops(vehicle))
            for index in range(pending - 1, 0 if stopped else -1, -1):
                vehicle_api.replaceStop(vehicle, index, "")  # an empty edge deletes it
            if loop is not None:
                vehicle_api.setRoute(vehicle, loop)
            else:
                vehicle_api.changeTarget(vehicle, edge)
            stop()
            if stopped:
                vehicle_api.resume(vehicle)
        except self._error as exc:
            raise SimulationError(f"cannot send {vehicle} to {where}: {exc}") from None

    def parked_in(self, area: str) -> list[str]:
        return sorted(str(v) for v in self.api.parkingarea.getVehicleIDs(area))

    def _stop_lane(self, edge: str) -> int:
        """The rightmost lane of ``edge`` open to passenger cars."""
        lane = self._lanes.get(edge)
        if lane is None:
            lane = 0
            for index in range(int(self.api.edge.getLaneNumber(edge))):
                allowed = self.api.lane.getAllowed(f"{edge}_{index}")
                if not allowed or "passenger" in allowed:
                    lane = index
                    break
            self._lanes[edge] = lane
        return lane

    def _loop(self, here: str, edge: str, vtype: str) -> list[str]:
        """The fastest route for vehicle type ``vtype`` from ``here`` that leaves the edge
        and comes back to ``edge``."""
        best: list[str] = []
        best_time = math.inf
        for lane in range(int(self.api.edge.getLaneNumber(here))):
            for link in self.api.lane.getLinks(f"{here}_{lane}"):
                following = str(link[0]).rsplit("_", 1)[0]
                try:
                    route = self.api.simulation.findRoute(following, edge, vType=vtype)
                except self._error:  # an edge this type may not use
                    continue
                if route.edges and route.travelTime < best_time:
                    best, best_time = [here, *route.edges], float(route.travelTime)
        if not best:
            raise SimulationError(f"no route from {here} back to {edge}")
        return best

    def vehicle_places(self) -> list[tuple[str, str, float]]:
        vehicle_api = self.api.vehicle
        places = []
        for vehicle in sorted(str(v) for v in vehicle_api.getIDList()):
            road = str(vehicle_api.getRoadID(vehicle))
            if road and not road.startswith(":"):
                places.append((vehicle, road, float(vehicle_api.getLanePosition(vehicle))))
        return places

    def edge_travel_times(self, edges: Sequence[str]) -> list[float]:
        get = self.api.edge.getTraveltime
        return [float(get(e)) for e in edges]

    def close(self) -> None:
        if self._api is not None:
            self._api.close()
            self._api = None


class LibsumoBackend(_ApiBackend):
    """SUMO in this process through libsumo (one simulation per process)."""

    def start(self, args: Sequence[str]) -> None:
        import libsumo

        try:
            libsumo.start(["sumo", *args])
        except libsumo.TraCIException as exc:
            raise SimulationError(f"SUMO did not start: {exc}") from None
        self._api = libsumo
        self._error = libsumo.TraCIException


_labels = itertools.count()


class TraciBackend(_ApiBackend):
    """SUMO (or ``sumo-gui`` with ``gui=True``) as a child process over TraCI."""

    def __init__(self, *, gui: bool = False) -> None:
        super().__init__()
        self.gui = gui

    def start(self, args: Sequence[str]) -> None:
        import sumolib
        import traci

        binary = sumolib.checkBinary("sumo-gui" if self.gui else "sumo")
        label = f"routing_svc_{next(_labels)}"
        extra = ["--start", "--quit-on-end"] if self.gui else []
        try:
            traci.start([binary, *args, *extra], label=label)
        except (traci.TraCIException, traci.FatalTraCIError) as exc:
            raise SimulationError(f"SUMO did not start: {exc}") from None
        self._api = traci.getConnection(label)
        self._error = traci.TraCIException


def make_backend(kind: str, *, gui: bool = False) -> SimBackend:
    """``"libsumo"`` or ``"traci"`` (``gui=True`` implies traci with ``sumo-gui``)."""
    if gui or kind == "traci":
        return TraciBackend(gui=gui)
    if kind == "libsumo":
        return LibsumoBackend()
    raise SimulationError(f"backend must be 'libsumo' or 'traci', got {kind!r}")
