"""Dispatch SUMO's taxi reservations by asking the fleet service.

After every simulation step, :meth:`FleetDispatcher.on_step`:

1. pushes SUMO's current edge travel times to the fleet every
   ``traffic_period`` seconds (``PUT .../traveltimes``), if asked to;
2. for each new reservation (a person asking for a ride), asks the service
   which vehicle serves it: ``POST .../targets`` (the SA update; the ``sa``
   policy) or ``POST .../assign`` (no update; ``static`` and ``optimum``).
   The vehicle whose *reference position* reaches the target first serves it.
   If that vehicle is busy, the closest idle vehicle by SUMO's current travel
   times serves it instead (a *fallback*, counted); if none is idle, the
   request waits in a queue for the next vehicle that becomes idle;
3. sends every vehicle that has just finished a job back to its current
   (possibly updated) reference position, or to the oldest queued request.

Idle vehicles (SUMO's ``device.taxi.state`` 0) are those parked at their
reference and those driving back to it.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from routing_svc.client import FleetClient
from routing_svc.sim.backend import (
    TAXI_GONE,
    TAXI_IDLE,
    Reservation,
    SimBackend,
    SimulationError,
)
from routing_svc.sim.inputs import FLEET_TYPE

__all__ = ["DispatchLog", "FleetDispatcher", "Snapshot"]

#: Live travel times are clipped to at most this multiple of the free-flow time.
MAX_SLOWDOWN = 20.0

Position = tuple[str, float]


@dataclass(frozen=True, slots=True)
class Snapshot:
    """The reference positions at one simulated time."""

    time: float
    positions: dict[str, Position]


@dataclass(slots=True)
class DispatchLog:
    """What the dispatcher did during a run."""

    requests: int = 0
    fallbacks: int = 0
    """Requests whose chosen vehicle was busy, served by another one."""
    queued: int = 0
    """Requests that found no idle vehicle at all and waited for one."""
    failed: int = 0
    """Requests SUMO refused to dispatch (none expected)."""
    park_retries: int = 0
    """Times SUMO could not send a vehicle home at once (it was tried again a step later)."""
    lost: list[str] = field(default_factory=list)
    """Fleet vehicles that left the simulation (never expected; counted, not fatal)."""
    traffic_updates: int = 0
    chosen: dict[str, str] = field(default_factory=dict)
    """Person id -> the vehicle the service chose."""
    dispatched: dict[str, str] = field(default_factory=dict)
    """Person id -> the vehicle sent."""
    predicted: dict[str, float] = field(default_factory=dict)
    """Person id -> the service's completion time ``T`` from the reference position."""
    snapshots: list[Snapshot] = field(default_factory=list)


def _position(data: Mapping[str, Any]) -> Position:
    return (str(data["edge"]), float(data["offset"]))


class FleetDispatcher:
    """Serve SUMO's taxi reservations with the vehicles the fleet service chooses.

    Parameters
    ----------
    backend : SimBackend
        The running simulation (dispatch algorithm ``traci``).
    client : FleetClient
        The fleet service, in-process or over HTTP.
    fleet_id : str
        The fleet whose vehicles are SUMO's fleet vehicles (same ids).
    learn : bool
        ``True``: post each request as a target (SA update); ``False``: only
        ask who serves it (frozen reference positions).
    traffic_edges : Mapping[str, float], optional
        SUMO edge id -> free-flow travel time (s) of the edges to push live
        travel times for; ``None`` pushes nothing.
    traffic_period : float
        Seconds between two pushes of live travel times.
    snapshot_period : float
        Seconds between two records of the reference positions.
    """

    def __init__(
        self,
        backend: SimBackend,
        client: FleetClient,
        fleet_id: str,
        *,
        learn: bool,
        traffic_edges: Mapping[str, float] | None = None,
        traffic_period: float = 60.0,
        snapshot_period: float = 300.0,
    ) -> None:
        self.backend = backend
        self.client = client
        self.fleet_id = fleet_id
        self.learn = learn
        self.traffic_edges = dict(traffic_edges) if traffic_edges is not None else None
        self.traffic_period = traffic_period
        self.snapshot_period = snapshot_period
        fleet = client.get_fleet(fleet_id)
        self.references: dict[str, Position] = {
            str(v["id"]): _position(v["position"]) for v in fleet["vehicles"]
        }
        self.busy: set[str] = set()
        self.gone: set[str] = set()
        self.homeless: set[str] = set()
        self.queue: deque[Reservation] = deque()
        self.log = DispatchLog()
        self._next_traffic = 0.0
        self._next_snapshot = 0.0

    def on_step(self) -> None:
        """Do everything due after one simulation step."""
        now = self.backend.time()
        if self.traffic_edges is not None and now >= self._next_traffic:
            self._push_travel_times()
            self._next_traffic = now + self.traffic_period
        if now >= self._next_snapshot:
            self.log.snapshots.append(Snapshot(now, dict(self.references)))
            self._next_snapshot = now + self.snapshot_period
        for reservation in self.backend.new_reservations():
            self._request(reservation)
        self._release_finished()

    def finish(self) -> None:
        """Record the final reference positions."""
        self.log.snapshots.append(Snapshot(self.backend.time(), dict(self.references)))

    def _push_travel_times(self) -> None:
        assert self.traffic_edges is not None
        edges = list(self.traffic_edges)
        live = self.backend.edge_travel_times(edges)
        times = {}
        for edge, seconds in zip(edges, live, strict=True):
            free = self.traffic_edges[edge]
            value = seconds if math.isfinite(seconds) else free * MAX_SLOWDOWN
            times[edge] = min(max(value, free), free * MAX_SLOWDOWN)
        self.client.put_traveltimes(self.fleet_id, times)
        self.log.traffic_updates += 1

    def _request(self, reservation: Reservation) -> None:
        position = {"edge": reservation.from_edge, "offset": reservation.from_pos}
        if self.learn:
            answer = self.client.post_target(self.fleet_id, position)
            for moved_back in answer.get("backed_off", ()):
                self.references[str(moved_back["vehicle"])] = _position(moved_back["position"])
            self.references[str(answer["moved"])] = _position(answer["new_position"])
        else:
            answer = self.client.assign(self.fleet_id, position)
        chosen = str(answer["served_by"][0])
        self.log.requests += 1
        self.log.chosen[reservation.person] = chosen
        self.log.predicted[reservation.person] = float(answer["cost"])
        if chosen not in self.busy and chosen not in self.gone:
            self._send(chosen, reservation)
            return
        idle = self._idle()
        if not idle:
            self.log.queued += 1
            self.queue.append(reservation)
            return
        self.log.fallbacks += 1
        self._send(self._closest(idle, reservation), reservation)

    def _closest(self, idle: Sequence[str], reservation: Reservation) -> str:
        """The idle vehicle with the fastest route to the pick-up (ties: by id)."""
        best, best_time = idle[0], math.inf
        for vehicle in sorted(idle):
            if self.backend.taxi_state(vehicle) == TAXI_GONE:
                self._lose(vehicle)
                continue
            here = self.backend.current_edge(vehicle)
            seconds = self.backend.route_time(here, reservation.from_edge, FLEET_TYPE)
            if seconds < best_time:
                best, best_time = vehicle, seconds
        return best

    def _send(self, vehicle: str, reservation: Reservation) -> None:
        try:
            self.backend.dispatch(vehicle, reservation.id)
        except SimulationError:
            if self.backend.taxi_state(vehicle) != TAXI_GONE:
                self.log.failed += 1
                return
            self._lose(vehicle)
            idle = self._idle()
            if idle:
                self._send(self._closest(idle, reservation), reservation)
            else:
                self.queue.appendleft(reservation)
            return
        self.busy.add(vehicle)
        self.log.dispatched[reservation.person] = vehicle

    def _lose(self, vehicle: str) -> None:
        """Forget a vehicle that has left the simulation."""
        if vehicle not in self.gone:
            self.gone.add(vehicle)
            self.log.lost.append(vehicle)
        self.busy.discard(vehicle)
        self.homeless.discard(vehicle)

    def _release_finished(self) -> None:
        if not self.busy:
            if self.homeless:
                self._send_home()
            return
        states = {v: self.backend.taxi_state(v) for v in sorted(self.busy)}
        for vehicle, state in states.items():
            if state == TAXI_GONE:
                self._lose(vehicle)
        done = [v for v, state in states.items() if state == TAXI_IDLE]
        for vehicle in done:
            self.busy.discard(vehicle)
        while self.queue and self._idle():
            reservation = self.queue.popleft()
            chosen = self.log.chosen[reservation.person]
            idle = self._idle()
            vehicle = chosen if chosen in idle else self._closest(idle, reservation)
            if vehicle != chosen:
                self.log.fallbacks += 1
            self._send(vehicle, reservation)
        self.homeless.update(v for v in done if v not in self.busy)
        self._send_home()

    def _idle(self) -> list[str]:
        """Vehicles that are neither busy nor gone, by id."""
        return [v for v in sorted(self.references) if v not in self.busy and v not in self.gone]

    def _send_home(self) -> None:
        """Send idle vehicles that have not been sent home yet to their reference."""
        for vehicle in sorted(self.homeless):
            self.homeless.discard(vehicle)
            if vehicle in self.busy or vehicle in self.gone:
                continue
            if self.backend.taxi_state(vehicle) == TAXI_GONE:
                self._lose(vehicle)
                continue
            edge, offset = self.references[vehicle]
            try:
                self.backend.park_at(vehicle, edge, offset)
            except SimulationError:
                self.log.park_retries += 1
                self.homeless.add(vehicle)
