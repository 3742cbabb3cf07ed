"""A deterministic stand-in for SUMO, for fast tests of the dispatch logic only.

:class:`FakeBackend` implements :class:`~routing_svc.sim.backend.SimBackend`
without any traffic: time advances one second per step, reservations appear
at scripted times, a dispatched vehicle is busy for a fixed number of seconds
and then idle at the request's destination edge, and route times come from a
given function. It measures nothing; every measured result in this project
comes from real SUMO runs (:class:`~routing_svc.sim.backend.LibsumoBackend`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

from routing_svc.sim.backend import TAXI_GONE, Reservation, SimulationError

__all__ = ["FakeBackend", "FakeDispatch"]


@dataclass(frozen=True, slots=True)
class FakeDispatch:
    """One dispatch the fake received."""

    time: float
    vehicle: str
    reservation: str


def _same_edge_or_minute(from_edge: str, to_edge: str) -> float:
    return 0.0 if from_edge == to_edge else 60.0


@dataclass
class FakeBackend:
    """Scripted reservations, fixed service times, no traffic.

    Parameters
    ----------
    positions : Mapping[str, str]
        Fleet vehicle id -> the edge it starts on.
    reservations : sequence of Reservation
        Appear at their ``time`` (whole seconds).
    service_seconds : float
        How long a dispatched vehicle stays busy.
    route_time : callable, optional
        ``(from_edge, to_edge) -> seconds``; default 0 on the same edge, else 60.
    """

    positions: Mapping[str, str]
    reservations: Sequence[Reservation]
    service_seconds: float = 120.0
    route_time_of: Callable[[str, str], float] = _same_edge_or_minute
    now: float = 0.0
    started: bool = False
    dispatches: list[FakeDispatch] = field(default_factory=list)
    parked: list[tuple[float, str, str, float]] = field(default_factory=list)
    pushes: int = 0
    _edges: dict[str, str] = field(default_factory=dict)
    _busy_until: dict[str, float] = field(default_factory=dict)
    _returned: int = 0
    _gone: set[str] = field(default_factory=set)

    def vanish(self, vehicle: str) -> None:
        """Take a vehicle out of the simulation (as SUMO does when a route ends)."""
        self._gone.add(vehicle)

    def start(self, args: Sequence[str]) -> None:
        self._edges = dict(self.positions)
        self.started = True

    def _check(self) -> None:
        if not self.started:
            raise SimulationError("the fake simulation has not been started")

    def step(self) -> None:
        self._check()
        self.now += 1.0

    def time(self) -> float:
        return self.now

    def close(self) -> None:
        self.started = False

    def new_reservations(self) -> list[Reservation]:
        self._check()
        due = sorted(self.reservations, key=lambda r: (r.time, r.person))
        fresh = [r for r in due[self._returned :] if r.time <= self.now]
        self._returned += len(fresh)
        return fresh

    def dispatch(self, vehicle: str, reservation: str) -> None:
        self._check()
        if self.taxi_state(vehicle) != 0:
            raise SimulationError(f"{vehicle} is busy or gone")
        target = next(r for r in self.reservations if r.id == reservation)
        self._busy_until[vehicle] = self.now + self.service_seconds
        self._edges[vehicle] = target.to_edge
        self.dispatches.append(FakeDispatch(self.now, vehicle, reservation))

    def taxi_state(self, vehicle: str) -> int:
        if vehicle in self._gone:
            return TAXI_GONE
        return 1 if self._busy_until.get(vehicle, -1.0) > self.now else 0

    def current_edge(self, vehicle: str) -> str:
        return self._edges[vehicle]

    def lane_position(self, vehicle: str) -> float:
        return 0.0

    def vehicle_position(self, vehicle: str) -> tuple[str, float]:
        return self._edges[vehicle], 0.0

    def route_time(self, from_edge: str, to_edge: str, vtype: str) -> float:
        return self.route_time_of(from_edge, to_edge)

    def park_at(self, vehicle: str, edge: str, offset: float) -> None:
        self.parked.append((self.now, vehicle, edge, offset))
        self._edges[vehicle] = edge

    def park_in(self, vehicle: str, area: str) -> None:
        raise SimulationError("the fake backend has no parkingAreas")

    def parked_in(self, area: str) -> list[str]:
        return []

    def vehicle_places(self) -> list[tuple[str, str, float]]:
        return [(v, e, 0.0) for v, e in sorted(self._edges.items())]

    def edge_travel_times(self, edges: Sequence[str]) -> list[float]:
        self.pushes += 1
        return [10.0 for _ in edges]
