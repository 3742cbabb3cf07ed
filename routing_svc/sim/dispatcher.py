"""Dispatch SUMO's taxi reservations with the vehicles the fleet service names.

The service decides who goes (the ``dispatch`` block of its answer: the
closest *available* vehicles by their current positions); SUMO drives them.
The co-simulation keeps the service's view of the vehicles true by reporting
their states as SUMO changes them (``PUT .../vehicles/state`` in batches):

- ``busy`` when a vehicle is dispatched;
- ``available`` at its drop-off, with its current position;
- the current position of an available vehicle that drives (back to its
  reference), every ``position_period`` seconds while it moves;
- ``offline`` if it leaves the simulation.

After every simulation step, :meth:`FleetDispatcher.on_step`:

1. pushes SUMO's current edge travel times every ``traffic_period`` seconds
   (``PUT .../traveltimes``), if asked to;
2. reports the vehicles that dropped their customer off as available and
   serves the waiting requests first, asking ``/assign`` again (read-only)
   for each (the request was already learnt from when it came): with
   ``queue_order="soonest"`` (default) first the oldest of those that waited
   past the reports' largest service-level threshold, else the one the
   vehicles named reach soonest; with ``"fifo"`` the oldest;
3. asks the service about each new reservation: ``POST .../targets`` (the
   SA learns from it; ``sa`` policies) or ``POST .../assign`` (frozen
   references; ``static``, ``optimum``). A ``dispatched`` answer sends the
   vehicle it names; ``queued`` (nobody available) puts the request in the
   queue; ``partial`` sends the vehicles named (the first carries the
   customer, the others drive to the pick-up and wait with it) and queues
   the rest;
4. with ``move_up``, whenever a vehicle became busy or available or a reference
   moved, asks where the available vehicles should wait (``GET .../posts``: the
   references that serve the demand best with as many vehicles as are free);
5. sends every idle vehicle whose home (its post with ``move_up``, else its
   reference) is elsewhere to it (after a drop-off, or when a learning step or
   the posts moved it); a fleet with stands
   sends it to its stand instead (the fleet's ``stands``, read again after
   every learning step), where it parks in the stand's SUMO parkingArea, or
   on the road beside it when the parkingArea has no room left (counted);
6. sends the state changes of the step in one batch.

Before any question to the service the staged changes are sent, so an
answer never names a vehicle that was dispatched a moment ago.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from routing_svc.client import FleetClient
from routing_svc.network.stands import Stand
from routing_svc.sim.backend import (
    TAXI_GONE,
    TAXI_IDLE,
    Reservation,
    SimBackend,
    SimulationError,
)
from routing_svc.sim.measures import DEFAULT_THRESHOLDS

#: How waiting requests are served when vehicles become available (:class:`FleetDispatcher`).
QUEUE_ORDERS = ("soonest", "fifo")

__all__ = ["DispatchLog", "FleetDispatcher", "Snapshot", "Waiting", "stand_homes"]

#: Live travel times are clipped to at most this multiple of the free-flow time.
MAX_SLOWDOWN = 20.0

#: A moving vehicle's position is reported again once it is this far (m) from the last report.
POSITION_TOLERANCE = 1.0

Position = tuple[str, float]


@dataclass(frozen=True, slots=True)
class Snapshot:
    """The reference positions at one simulated time."""

    time: float
    positions: dict[str, Position]


@dataclass(slots=True)
class Waiting:
    """A request that waits for vehicles.

    ``requires`` is what is still missing (``None``: any one vehicle);
    ``carrier`` the vehicle already sent that carries the customer, if any;
    ``orphaned`` whether a carrier left the simulation before the drop-off.
    """

    reservation: Reservation
    requires: tuple[str, ...] | None = None
    carrier: str | None = None
    orphaned: bool = False


@dataclass(slots=True)
class DispatchLog:
    """What the dispatcher did during a run."""

    requests: int = 0
    queued: int = 0
    """Requests whose first answer was ``queued`` or ``partial`` (they waited in the queue)."""
    partial: int = 0
    """Answers that sent some of the required vehicles and not all."""
    failed: int = 0
    """Dispatches SUMO refused (the request went back to the head of the queue)."""
    park_retries: int = 0
    """Times SUMO could not send a vehicle home at once (it was tried again a step later)."""
    lost: list[str] = field(default_factory=list)
    """Fleet vehicles that left the simulation (never expected; counted, not fatal)."""
    orphaned: list[str] = field(default_factory=list)
    """Persons whose carrier left the simulation; asked for again at the head of the queue."""
    dropped: list[str] = field(default_factory=list)
    """Orphaned persons SUMO would not let another vehicle serve."""
    traffic_updates: int = 0
    state_batches: int = 0
    """Batches of vehicle states sent to the service."""
    unparked: int = 0
    """Vehicles sent to a stand whose parkingArea had no room left (they waited on the road)."""
    state_changes: list[tuple[float, str, str]] = field(default_factory=list)
    """``(time, vehicle, status)`` of every state change sent (positions left out)."""
    named: dict[str, str] = field(default_factory=dict)
    """Person id -> the vehicle the service's dispatch answer named to carry them."""
    dispatched: dict[str, str] = field(default_factory=dict)
    """Person id -> the vehicle SUMO was told to send."""
    from_queue: list[str] = field(default_factory=list)
    """Persons served from the queue, in the order they were sent."""
    predicted: dict[str, float] = field(default_factory=dict)
    """Person id -> the service's travel time of the carrier from its current position."""
    snapshots: list[Snapshot] = field(default_factory=list)


def _position(data: Mapping[str, Any]) -> Position:
    return (str(data["edge"]), float(data["offset"]))


def stand_homes(
    fleet: Mapping[str, Any], stands: Sequence[Stand]
) -> dict[str, tuple[Position, Stand]]:
    """Each vehicle's stand in a fleet answer (its ``stands``), and the parkingArea it parks in.

    ``stands`` are the parkingAreas the fleet's stands were made of; where
    several share a position (one stand of the fleet, capacities added), the
    stand's vehicles, by id, fill them in order.

    Raises
    ------
    SimulationError
        The fleet has no stands, or a stand at no position of ``stands``.
    """
    by_position: dict[Position, list[Stand]] = {}
    for stand in stands:
        by_position.setdefault((stand.edge, stand.offset), []).append(stand)
    if not fleet.get("stands"):
        raise SimulationError(f"fleet {fleet.get('id')!r} has no stands")
    homes: dict[str, tuple[Position, Stand]] = {}
    for answer in fleet["stands"]:
        position = _position(answer["position"])
        areas = by_position.get(position)
        if not areas:
            raise SimulationError(f"the fleet's stand at {position} is no parkingArea given")
        slots = [area for area in areas for _ in range(area.capacity)]
        for vehicle, area in zip(sorted(answer["vehicles"]), slots, strict=False):
            homes[str(vehicle)] = (position, area)
    return homes


class FleetDispatcher:
    """Serve SUMO's taxi reservations with the vehicles the fleet service dispatches.

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
    edge_lengths : Mapping[str, float], optional
        The service network's edges and their lengths: positions on other
        edges (or on junctions) are not reported. ``None``: every edge, offsets
        unclipped.
    requires : sequence of str, optional
        The vehicle types every request needs (``None``: any one vehicle).
    traffic_edges : Mapping[str, float], optional
        SUMO edge id -> free-flow travel time (s) of the edges to push live
        travel times for; ``None`` pushes nothing.
    traffic_period : float
        Seconds between two pushes of live travel times.
    snapshot_period : float
        Seconds between two records of the reference positions.
    position_period : float
        Seconds between two reports of the positions of available vehicles that drive.
    stands : sequence of Stand, optional
        The parkingAreas the fleet's stands were made of: idle vehicles park
        in them (:func:`stand_homes`). ``None``: they park at their references.
    move_up : bool
        Idle vehicles wait at the posts the service names (``GET .../posts``)
        instead of their own references; not with ``stands``.
    queue_order : {"soonest", "fifo"}
        Which waiting request available vehicles serve next (:meth:`_next_waiting`).
    overdue_after : float
        ``soonest``: seconds after which a waiting request goes before the others
        (the reports' largest service-level threshold).
    """

    def __init__(
        self,
        backend: SimBackend,
        client: FleetClient,
        fleet_id: str,
        *,
        learn: bool,
        edge_lengths: Mapping[str, float] | None = None,
        requires: Sequence[str] | None = None,
        traffic_edges: Mapping[str, float] | None = None,
        traffic_period: float = 60.0,
        snapshot_period: float = 300.0,
        position_period: float = 30.0,
        stands: Sequence[Stand] | None = None,
        move_up: bool = False,
        queue_order: str = "soonest",
        overdue_after: float = max(DEFAULT_THRESHOLDS),
    ) -> None:
        if queue_order not in QUEUE_ORDERS:
            raise ValueError(f"queue_order must be one of {QUEUE_ORDERS}, not {queue_order!r}")
        self.queue_order = queue_order
        self.overdue_after = overdue_after
        self.backend = backend
        self.client = client
        self.fleet_id = fleet_id
        self.learn = learn
        self.edge_lengths = dict(edge_lengths) if edge_lengths is not None else None
        self.requires = tuple(requires) if requires else None
        self.traffic_edges = dict(traffic_edges) if traffic_edges is not None else None
        self.traffic_period = traffic_period
        self.snapshot_period = snapshot_period
        self.position_period = position_period
        self.stands = tuple(stands) if stands is not None else None
        self.move_up = move_up and stands is None
        self.posts: dict[str, Position] = {}
        """With ``move_up``: where each available vehicle waits now."""
        self._posts_due = self.move_up
        self.references: dict[str, Position] = {}
        """Where each idle vehicle waits: its reference, or its stand with stands."""
        self.areas: dict[str, Stand] = {}
        """With stands: each vehicle's parkingArea."""
        self.sent_to: dict[str, str] = {}
        """Idle vehicles sent to (or parked in) a parkingArea, and its id."""
        self._read_references()
        self.busy: set[str] = set()
        self.escorts: dict[str, str] = {}
        """Vehicle -> the carrier it accompanies (partial answers): released together."""
        self.carrying: dict[str, Waiting] = {}
        """Carrier -> the request it serves, until its drop-off."""
        self.gone: set[str] = set()
        self.homeless: set[str] = set()
        self.reported: dict[str, Position] = {}
        self.queue: deque[Waiting] = deque()
        self.log = DispatchLog()
        self._staged: list[dict[str, Any]] = []
        self._next_traffic = 0.0
        self._next_snapshot = 0.0
        self._next_positions = 0.0
        self._retry = False

    # -- the step -------------------------------------------------------------

    def on_step(self) -> None:
        """Do everything due after one simulation step."""
        now = self.backend.time()
        if self.traffic_edges is not None and now >= self._next_traffic:
            self._push_travel_times()
            self._next_traffic = now + self.traffic_period
        if now >= self._next_snapshot:
            self.log.snapshots.append(Snapshot(now, dict(self.references)))
            self._next_snapshot = now + self.snapshot_period
        if self._release_finished() or self._retry:
            self._retry = False
            self._serve_queue()
        for reservation in self.backend.new_reservations():
            self._request(reservation)
        if self._posts_due:
            self._read_posts()
        self._send_home()
        if now >= self._next_positions:
            self._report_moving()
            self._next_positions = now + self.position_period
        self._flush()

    def finish(self) -> None:
        """Send what is staged and record the final reference positions."""
        self._flush()
        self.log.snapshots.append(Snapshot(self.backend.time(), dict(self.references)))

    # -- the service ----------------------------------------------------------

    def _stage(self, vehicle: str, status: str, *, position: Position | None = None) -> None:
        change: dict[str, Any] = {
            "vehicle": vehicle,
            "status": status,
            "timestamp": self.backend.time(),
        }
        if position is not None:
            change["position"] = {"edge": position[0], "offset": position[1]}
            self.reported[vehicle] = position
        self._staged.append(change)
        self.log.state_changes.append((self.backend.time(), vehicle, status))

    def _flush(self) -> None:
        """Send the staged state changes in one batch."""
        if not self._staged:
            return
        changes, self._staged = self._staged, []
        self.client.put_vehicle_states(self.fleet_id, changes)
        self.log.state_batches += 1

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

    def _read_references(self) -> None:
        fleet = self.client.get_fleet(self.fleet_id)
        if self.stands is not None:
            homes = stand_homes(fleet, self.stands)
            self.areas = {vehicle: area for vehicle, (_, area) in homes.items()}
            self._update_references({vehicle: p for vehicle, (p, _) in homes.items()})
            return
        moved = {
            str(v["id"]): _position(v.get("reference") or v["position"]) for v in fleet["vehicles"]
        }
        self._update_references(moved)

    def _update_references(self, moved: Mapping[str, Position]) -> None:
        """New references; an idle vehicle whose reference moved drives to the new one
        (with ``move_up``: the posts are asked for again)."""
        for vehicle, position in moved.items():
            before = self.references.get(vehicle)
            self.references[vehicle] = position
            if before is not None and before != position:
                self._posts_changed()
                if vehicle not in self.busy and not self.move_up:
                    self.homeless.add(vehicle)

    def _posts_changed(self) -> None:
        """Availability or a reference changed: with ``move_up``, ask for the posts again
        at the end of the step."""
        self._posts_due = self.move_up

    def _read_posts(self) -> None:
        """Ask where the available vehicles should wait; those whose post changed drive
        to the new one."""
        self._posts_due = False
        self._flush()
        for post in self.client.posts(self.fleet_id)["posts"]:
            vehicle = str(post["vehicle"])
            position = _position(post["position"])
            if vehicle in self.busy or vehicle in self.gone:
                continue
            if self.posts.get(vehicle, self.references.get(vehicle)) != position:
                self.homeless.add(vehicle)
            self.posts[vehicle] = position

    def _ask(self, reservation: Reservation, requires: Sequence[str] | None, *, learn: bool) -> Any:
        """The service's answer for a request (after sending the staged states)."""
        self._flush()
        position = {"edge": reservation.from_edge, "offset": reservation.from_pos}
        needs = list(requires) if requires else None
        if not learn:
            return self.client.assign(self.fleet_id, position, requires=needs)
        answer = self.client.post_target(self.fleet_id, position, requires=needs)
        if answer.get("consolidated") or self.stands is not None:
            self._read_references()
        else:
            moved = {str(b["vehicle"]): _position(b["position"]) for b in answer["backed_off"]}
            moved[str(answer["moved"])] = _position(answer["new_position"])
            self._update_references(moved)
        return answer

    # -- requests -------------------------------------------------------------

    def _request(self, reservation: Reservation) -> None:
        self.log.requests += 1
        answer = self._ask(reservation, self.requires, learn=self.learn)
        waiting = Waiting(reservation, self.requires)
        if not self._serve(waiting, answer["dispatch"]):
            self.log.queued += 1
            self.queue.append(waiting)

    def _serve_queue(self) -> None:
        """Serve waiting requests, one at a time (:meth:`_next_waiting`), while the service
        names vehicles for them."""
        while self.queue:
            chosen = self._next_waiting()
            if chosen is None:
                return
            waiting, dispatch = chosen
            self.queue.remove(waiting)
            if not self._serve(waiting, dispatch):
                self.queue.appendleft(waiting)
                return
            self.log.from_queue.append(waiting.reservation.person)

    def _next_waiting(self) -> tuple[Waiting, Mapping[str, Any]] | None:
        """The waiting request to serve next and the service's dispatch for it (``None``:
        the service names nobody).

        ``fifo``: the head of the queue (the oldest; a request whose dispatch failed
        goes back to the head). ``soonest``: the head if it waited
        :attr:`overdue_after` seconds or more; else, of the requests the service names
        vehicles for, the one they reach soonest (the largest ``cost`` among its
        dispatched vehicles; ties to the older). Serving the closest request first
        shortens the empty drives, so the fleet serves more requests an hour when
        it is saturated; the overdue rule bounds how long a far request waits.
        """
        head = self.queue[0]
        overdue = self.backend.time() - head.reservation.time >= self.overdue_after
        if self.queue_order == "fifo" or overdue:
            dispatch = self._ask(head.reservation, head.requires, learn=False)["dispatch"]
            return None if dispatch["status"] == "queued" else (head, dispatch)
        best: tuple[float, Waiting, Mapping[str, Any]] | None = None
        for waiting in self.queue:
            dispatch = self._ask(waiting.reservation, waiting.requires, learn=False)["dispatch"]
            if dispatch["status"] == "queued":
                continue
            arrival = max(float(v["cost"]) for v in dispatch["vehicles"])
            if best is None or arrival < best[0]:
                best = (arrival, waiting, dispatch)
        return None if best is None else (best[1], best[2])

    def _serve(self, waiting: Waiting, dispatch: Mapping[str, Any]) -> bool:
        """Send the vehicles a dispatch answer names; whether the request is complete.

        The first vehicle sent carries the customer (SUMO's ``dispatchTaxi``);
        further vehicles drive to the pick-up and stay busy until the carrier
        is done. What the answer leaves missing stays in ``waiting``.
        """
        sent = [str(v["vehicle"]) for v in dispatch["vehicles"]]
        if dispatch["status"] == "partial":
            self.log.partial += 1
        person = waiting.reservation.person
        for vehicle in sent:
            if waiting.carrier is None:
                if not self._dispatch(vehicle, waiting.reservation):
                    if waiting.orphaned:  # SUMO no longer offers it (e.g. picked up)
                        self.log.dropped.append(person)
                        return True
                    return False
                waiting.carrier = vehicle
                self.carrying[vehicle] = waiting
                self.log.named[person] = vehicle
                self.log.predicted[person] = float(dispatch["vehicles"][0]["cost"])
            else:
                self._escort(vehicle, waiting)
        missing = tuple(str(t) for t in dispatch["missing"])
        if missing and waiting.requires is not None:
            waiting.requires = missing
        return not missing

    def _dispatch(self, vehicle: str, reservation: Reservation) -> bool:
        """Tell SUMO to send ``vehicle``; report it busy. ``False`` if SUMO refused."""
        try:
            self.backend.dispatch(vehicle, reservation.id)
        except SimulationError:
            if self.backend.taxi_state(vehicle) == TAXI_GONE:
                self._lose(vehicle)
            else:
                self.log.failed += 1
            self._retry = True
            return False
        self.busy.add(vehicle)
        self.homeless.discard(vehicle)
        self.sent_to.pop(vehicle, None)
        self._posts_changed()
        self.log.dispatched[reservation.person] = vehicle
        self._stage(vehicle, "busy")
        return True

    def _escort(self, vehicle: str, waiting: Waiting) -> None:
        """Send a further required vehicle to the pick-up; it stays with the carrier."""
        assert waiting.carrier is not None
        reservation = waiting.reservation
        self.busy.add(vehicle)
        self.homeless.discard(vehicle)
        self.sent_to.pop(vehicle, None)
        self._posts_changed()
        self.escorts[vehicle] = waiting.carrier
        self._stage(vehicle, "busy")
        try:
            self.backend.park_at(vehicle, reservation.from_edge, reservation.from_pos)
        except SimulationError:
            self.log.park_retries += 1

    # -- vehicles -------------------------------------------------------------

    def _lose(self, vehicle: str) -> None:
        """Forget a vehicle that has left the simulation; tell the service it is offline."""
        if vehicle not in self.gone:
            self.gone.add(vehicle)
            self.log.lost.append(vehicle)
            self._stage(vehicle, "offline")
            self._posts_changed()
        self.busy.discard(vehicle)
        self.homeless.discard(vehicle)
        self.sent_to.pop(vehicle, None)

    def place(self, vehicle: str) -> Position | None:
        """Where a vehicle is now, on the service's network (``None``: not on it now)."""
        edge, offset = self.backend.vehicle_position(vehicle)
        if self.edge_lengths is None:
            return (edge, offset)
        length = self.edge_lengths.get(edge)
        if length is None:
            return None
        return (edge, min(max(offset, 0.0), length))

    def _release_finished(self) -> bool:
        """Report vehicles that finished their job as available; whether any did."""
        carriers = sorted(v for v in self.busy if v not in self.escorts)
        states = {v: self.backend.taxi_state(v) for v in carriers}
        done = []
        lost = []
        for vehicle, state in states.items():
            if state == TAXI_GONE:
                self._lose(vehicle)
                lost.append(vehicle)
            elif state == TAXI_IDLE:
                done.append(vehicle)
        for vehicle in lost:
            orphan = self.carrying.pop(vehicle, None)
            if orphan is not None:
                orphan.carrier, orphan.orphaned = None, True
                self.queue.appendleft(orphan)
                self.log.orphaned.append(orphan.reservation.person)
                self._retry = True
        done += sorted(e for e, carrier in self.escorts.items() if carrier in done + lost)
        for vehicle in done:
            self.busy.discard(vehicle)
            self.escorts.pop(vehicle, None)
            self.carrying.pop(vehicle, None)
            self._stage(vehicle, "available", position=self.place(vehicle))
            self.homeless.add(vehicle)
            self._posts_changed()
        return bool(done)

    def _report_moving(self) -> None:
        """Report the positions of available vehicles that moved since their last report."""
        for vehicle in sorted(self.references):
            if vehicle in self.busy or vehicle in self.gone:
                continue
            if self.backend.taxi_state(vehicle) == TAXI_GONE:
                self._lose(vehicle)
                continue
            here = self.place(vehicle)
            last = self.reported.get(vehicle)
            if here is None or last is None:
                continue
            if here[0] != last[0] or abs(here[1] - last[1]) > POSITION_TOLERANCE:
                self._stage(vehicle, "available", position=here)

    def _send_home(self) -> None:
        """Send idle vehicles that have not been sent home yet to their reference."""
        for vehicle in sorted(self.homeless):
            self.homeless.discard(vehicle)
            if vehicle in self.busy or vehicle in self.gone:
                continue
            if self.backend.taxi_state(vehicle) == TAXI_GONE:
                self._lose(vehicle)
                continue
            try:
                self._park(vehicle)
            except SimulationError:
                self.log.park_retries += 1
                self.homeless.add(vehicle)
                continue
            here = self.place(vehicle)
            if here is not None and self.reported.get(vehicle) != here:
                self._stage(vehicle, "available", position=here)

    def _park(self, vehicle: str) -> None:
        """Send an idle vehicle to its stand's parkingArea if it has room, else to its
        reference (or stand) on the road."""
        self.sent_to.pop(vehicle, None)
        area = self.areas.get(vehicle) if self.stands is not None else None
        if area is not None:
            others = set(self.backend.parked_in(area.id))
            others.update(v for v, a in self.sent_to.items() if a == area.id)
            others.discard(vehicle)
            if len(others) < area.capacity:
                self.backend.park_in(vehicle, area.id)
                self.sent_to[vehicle] = area.id
                return
            self.log.unparked += 1
        edge, offset = self.posts.get(vehicle, self.references[vehicle])
        self.backend.park_at(vehicle, edge, offset)
