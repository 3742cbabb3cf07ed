"""What SUMO measured: waits from ``personinfo``, distances from the taxis' ``tripinfo``.

:func:`read_tripinfo` reads one run's SUMO output; :class:`PolicyRun` is what a
co-simulation run reports (SUMO's measures plus the dispatcher's counts).

Every wait in a co-simulation report is read from SUMO's own tripinfo output
(``--tripinfo-output`` with ``--tripinfo-output.write-unfinished``), never
computed by the product: a request's wait is the ``waitingTime`` of its
person's ``<ride>`` stage, the time from the request (the person's arrival at
the pick-up point) until the taxi picked the person up. A ride with
``vehicle="NULL"`` was not picked up before the end; its ``waitingTime`` is
the (censored) time waited so far.

A fleet vehicle's empty distance is its ``routeLength`` minus the distance
driven with a customer on board (``<taxi occupiedDistance=...>``): driving to
pick-ups, back to reference positions, or circling.

Service levels (:func:`service_levels`) are over every request made in the
measured period: a request SUMO never served counts as an infinite wait, so it
is beyond every threshold and the percentiles do not flatter a policy that
leaves requests behind. Percentiles are nearest-rank (the smallest wait that at
least ``q`` % of the requests do not exceed). The load (:class:`FleetLoad`) is
sampled from SUMO's ``device.taxi.state`` of every fleet vehicle: busy when it
drives to a pick-up or carries a customer.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from defusedxml import ElementTree

from routing_svc.sim.backend import TAXI_GONE, TAXI_IDLE, SimBackend, SimulationError

__all__ = [
    "DEFAULT_THRESHOLDS",
    "FleetDistance",
    "FleetLoad",
    "PolicyRun",
    "RideRecord",
    "TripMeasures",
    "nearest_rank",
    "read_tripinfo",
    "service_levels",
]

#: Service-level thresholds (s) of the reports, the fleet service's defaults.
DEFAULT_THRESHOLDS = (300.0, 600.0, 900.0)


@dataclass(frozen=True, slots=True)
class RideRecord:
    """One request as SUMO's personinfo records it."""

    person: str
    requested: float
    """When the person asked for the ride (s)."""
    wait: float
    """SUMO's ``waitingTime`` of the ride (censored at the end if not picked up)."""
    vehicle: str | None
    """The taxi that picked the person up; ``None`` if none did."""

    @property
    def served(self) -> bool:
        return self.vehicle is not None


@dataclass(frozen=True, slots=True)
class FleetDistance:
    """One fleet vehicle's distances (m) from its tripinfo."""

    vehicle: str
    driven: float
    occupied: float
    customers: int
    left: bool = False
    """Whether the vehicle reached the end of a route and left SUMO before the end."""

    @property
    def empty(self) -> float:
        return max(self.driven - self.occupied, 0.0)


@dataclass(frozen=True, slots=True)
class TripMeasures:
    """Everything read from one run's tripinfo output."""

    rides: tuple[RideRecord, ...]
    fleet: tuple[FleetDistance, ...]

    @property
    def served(self) -> list[RideRecord]:
        return [r for r in self.rides if r.served]

    def mean_wait(self, *, since: float = -math.inf) -> float:
        """Mean wait of the served requests made at or after ``since`` (nan if none)."""
        waits = [r.wait for r in self.served if r.requested >= since]
        return math.fsum(waits) / len(waits) if waits else math.nan

    @property
    def empty_km(self) -> float:
        return math.fsum(f.empty for f in self.fleet) / 1000.0

    @property
    def driven_km(self) -> float:
        return math.fsum(f.driven for f in self.fleet) / 1000.0


def read_tripinfo(path: Path, *, fleet_prefix: str) -> TripMeasures:
    """Read the rides of every person and the distances of the fleet's vehicles.

    Parameters
    ----------
    path : Path
        SUMO's tripinfo output.
    fleet_prefix : str
        Fleet vehicle ids start with it (background vehicles are ignored).

    Raises
    ------
    SimulationError
        If the file is missing or malformed.
    """
    try:
        root = ElementTree.parse(path).getroot()
    except (OSError, ElementTree.ParseError) as exc:
        raise SimulationError(f"cannot read SUMO's tripinfo {path}: {exc}") from None
    rides: list[RideRecord] = []
    for person in root.iter("personinfo"):
        ride = person.find("ride")
        if ride is None:
            continue
        vehicle = ride.get("vehicle", "NULL")
        rides.append(
            RideRecord(
                person=str(person.get("id")),
                requested=float(person.get("depart", "nan")),
                wait=float(ride.get("waitingTime", "nan")),
                vehicle=None if vehicle in ("NULL", "") else vehicle,
            )
        )
    fleet: list[FleetDistance] = []
    for trip in root.iter("tripinfo"):
        vid = str(trip.get("id"))
        if not vid.startswith(fleet_prefix):
            continue
        taxi = trip.find("taxi")
        fleet.append(
            FleetDistance(
                vehicle=vid,
                driven=max(float(trip.get("routeLength", "0")), 0.0),
                occupied=0.0 if taxi is None else float(taxi.get("occupiedDistance", "0")),
                customers=0 if taxi is None else int(taxi.get("customers", "0")),
                left=float(trip.get("arrival", "-1")) >= 0.0,
            )
        )
    rides.sort(key=lambda r: (r.requested, r.person))
    fleet.sort(key=lambda f: f.vehicle)
    return TripMeasures(tuple(rides), tuple(fleet))


def nearest_rank(values: Sequence[float], q: float) -> float:
    """The nearest-rank ``q``-th percentile: the ``ceil(q/100 * n)``-th smallest value."""
    if not values:
        return math.nan
    ordered = sorted(values)
    rank = max(math.ceil(q / 100.0 * len(ordered)), 1)
    return ordered[rank - 1]


def service_levels(
    waits: Sequence[tuple[float, float, bool]],
    *,
    since: float,
    until: float = math.inf,
    thresholds: Sequence[float] = DEFAULT_THRESHOLDS,
) -> dict[str, Any]:
    """Wait percentiles and fractions within thresholds of the requests made in ``[since, until)``.

    Parameters
    ----------
    waits : sequence of (requested, wait, served)
        Every request, as :attr:`PolicyRun.waits`.

    Returns
    -------
    dict
        ``p50_wait_s``, ``p90_wait_s``, ``p95_wait_s`` (unserved requests count as
        infinite waits) and ``within`` (threshold as text -> fraction of the requests
        served within it).
    """
    counted = [w if served else math.inf for t, w, served in waits if since <= t < until]
    n = len(counted)
    return {
        "p50_wait_s": nearest_rank(counted, 50.0),
        "p90_wait_s": nearest_rank(counted, 90.0),
        "p95_wait_s": nearest_rank(counted, 95.0),
        "within": {
            f"{limit:g}": (sum(1 for w in counted if w <= limit) / n if n else math.nan)
            for limit in thresholds
        },
    }


class FleetLoad:
    """How busy the fleet is: SUMO's taxi states sampled every ``period`` seconds.

    Samples are taken in ``[since, until)`` of the vehicles still in the
    simulation; :attr:`busy_fraction` is the share of samples with a taxi
    driving to a pick-up or carrying a customer.
    """

    def __init__(
        self, vehicles: Sequence[str], *, since: float, until: float, period: float = 10.0
    ) -> None:
        self.vehicles = tuple(vehicles)
        self.since = since
        self.until = until
        self.period = period
        self.samples = 0
        self.busy = 0
        self._next = since

    def sample(self, backend: SimBackend) -> None:
        """Take a sample if one is due now."""
        now = backend.time()
        if now < self._next or now >= self.until:
            return
        self._next = now + self.period
        for vehicle in self.vehicles:
            state = backend.taxi_state(vehicle)
            if state == TAXI_GONE:
                continue
            self.samples += 1
            self.busy += state != TAXI_IDLE

    @property
    def busy_fraction(self) -> float:
        return self.busy / self.samples if self.samples else math.nan


@dataclass(slots=True)
class PolicyRun:
    """What one run measured (JSON-ready through :meth:`summary`)."""

    policy: str
    seed: int
    requests: int
    served: int
    mean_wait: float
    """Mean SUMO wait (s) of the served requests made after ``measure_from``."""
    mean_wait_second_half: float
    """The same over the second half of the request period."""
    empty_km: float
    driven_km: float
    fallbacks: int
    """Requests SUMO served with another vehicle than the service's dispatch answer named
    (service policies; expected 0)."""
    queued: int
    """Requests that found no available vehicle and waited in the dispatcher's queue."""
    failed: int
    sim_seconds: float
    wall_seconds: float
    tripinfo: str
    measure_from: float = 0.0
    """Requests before this time are not counted."""
    traffic_updates: int = 0
    park_retries: int = 0
    unparked: int = 0
    """Times an idle vehicle found no room in its stand's parkingArea (it waited on the road)."""
    lost: int = 0
    """Fleet vehicles that left the simulation before the end (SUMO's tripinfo)."""
    vehicles: int = 0
    """Fleet size."""
    request_hours: float = math.nan
    """Length (h) of the measured request period."""
    busy_fraction: float = math.nan
    """Share of the fleet's time in the request period spent going to or carrying customers."""
    thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS
    state_batches: int = 0
    """Batches of vehicle states the co-simulation sent to the service."""
    waits: list[tuple[float, float, bool]] = field(default_factory=list)
    """``(requested, wait, served)`` of every request, from SUMO's personinfo."""
    predicted: list[tuple[float, bool]] = field(default_factory=list)
    """Per request (same order): the service's travel time of the dispatched vehicle
    from its current position (free-flow or live seconds), and whether another vehicle
    went than the one the service named."""
    snapshots: list[tuple[float, dict[str, tuple[str, float]]]] = field(default_factory=list)
    """Reference positions over time (service policies only)."""

    @property
    def requests_per_vehicle_hour(self) -> float:
        """The load: requests in the measured period per vehicle and hour."""
        if not self.vehicles or not self.request_hours > 0.0:
            return math.nan
        return self.requests / (self.vehicles * self.request_hours)

    def service_levels(self) -> dict[str, Any]:
        """:func:`service_levels` of this run's requests in the measured period."""
        return service_levels(
            self.waits,
            since=self.measure_from,
            until=self.measure_from + self.request_hours * 3600.0,
            thresholds=self.thresholds,
        )

    @property
    def sim_speed(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.sim_seconds / self.wall_seconds if self.wall_seconds > 0 else math.inf

    def to_json(self) -> dict[str, Any]:
        """Everything, JSON-ready (the inverse of :meth:`from_json`)."""
        return {
            **self.summary(),
            "tripinfo": self.tripinfo,
            "waits": [list(w) for w in self.waits],
            "predicted": [list(p) for p in self.predicted],
            "snapshots": [[t, {k: list(v) for k, v in pos.items()}] for t, pos in self.snapshots],
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> PolicyRun:
        """A run saved with :meth:`to_json` (a number written ``null``, not finite, is
        read as NaN; the waits' percentiles are derived again from ``waits``)."""
        return cls(
            policy=str(data["policy"]),
            seed=int(data["seed"]),
            requests=int(data["requests"]),
            served=int(data["served"]),
            mean_wait=_number(data["mean_wait_s"]),
            mean_wait_second_half=_number(data["mean_wait_second_half_s"]),
            empty_km=_number(data["empty_km"]),
            driven_km=_number(data["driven_km"]),
            fallbacks=int(data["fallbacks"]),
            queued=int(data["queued"]),
            failed=int(data["failed"]),
            sim_seconds=_number(data["sim_seconds"]),
            wall_seconds=_number(data["wall_seconds"]),
            tripinfo=str(data["tripinfo"]),
            measure_from=float(data.get("measure_from", 0.0)),
            vehicles=int(data.get("vehicles", 0)),
            request_hours=_number(data.get("request_hours")),
            busy_fraction=_number(data.get("busy_fraction")),
            thresholds=tuple(float(t) for t in data.get("thresholds", DEFAULT_THRESHOLDS)),
            state_batches=int(data.get("state_batches", 0)),
            traffic_updates=int(data["traffic_updates"]),
            park_retries=int(data.get("park_retries", 0)),
            unparked=int(data.get("unparked", 0)),
            lost=int(data.get("lost", 0)),
            waits=[(_number(t), _number(w), bool(ok)) for t, w, ok in data["waits"]],
            predicted=[(_number(t), bool(other)) for t, other in data["predicted"]],
            snapshots=[
                (float(t), {k: (str(v[0]), float(v[1])) for k, v in pos.items()})
                for t, pos in data["snapshots"]
            ],
        )

    def summary(self) -> dict[str, Any]:
        """The headline numbers (no per-request data)."""
        levels = self.service_levels()
        return {
            "policy": self.policy,
            "seed": self.seed,
            "requests": self.requests,
            "served": self.served,
            "mean_wait_s": self.mean_wait,
            "p50_wait_s": levels["p50_wait_s"],
            "p90_wait_s": levels["p90_wait_s"],
            "p95_wait_s": levels["p95_wait_s"],
            "within": levels["within"],
            "mean_wait_second_half_s": self.mean_wait_second_half,
            "requests_per_vehicle_hour": self.requests_per_vehicle_hour,
            "busy_fraction": self.busy_fraction,
            "vehicles": self.vehicles,
            "request_hours": self.request_hours,
            "thresholds": list(self.thresholds),
            "measure_from": self.measure_from,
            "state_batches": self.state_batches,
            "empty_km": self.empty_km,
            "driven_km": self.driven_km,
            "fallbacks": self.fallbacks,
            "queued": self.queued,
            "failed": self.failed,
            "traffic_updates": self.traffic_updates,
            "park_retries": self.park_retries,
            "unparked": self.unparked,
            "lost": self.lost,
            "sim_seconds": self.sim_seconds,
            "wall_seconds": self.wall_seconds,
            "sim_speed": self.sim_speed,
        }


def _number(value: Any) -> float:
    """A saved number; ``None`` (JSON ``null``, how a non-finite one is written) is NaN."""
    return math.nan if value is None else float(value)
