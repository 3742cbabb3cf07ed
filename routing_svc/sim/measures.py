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
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from defusedxml import ElementTree

from routing_svc.sim.backend import SimulationError

__all__ = ["FleetDistance", "PolicyRun", "RideRecord", "TripMeasures", "read_tripinfo"]


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
    queued: int
    failed: int
    sim_seconds: float
    wall_seconds: float
    tripinfo: str
    traffic_updates: int = 0
    park_retries: int = 0
    lost: int = 0
    """Fleet vehicles that left the simulation before the end (SUMO's tripinfo)."""
    waits: list[tuple[float, float, bool]] = field(default_factory=list)
    """``(requested, wait, served)`` of every request, from SUMO's personinfo."""
    predicted: list[tuple[float, bool]] = field(default_factory=list)
    """Per request (same order): the service's completion time ``T`` from the chosen
    reference position (free-flow or live seconds), and whether another vehicle went."""
    snapshots: list[tuple[float, dict[str, tuple[str, float]]]] = field(default_factory=list)
    """Reference positions over time (service policies only)."""

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
        """A run saved with :meth:`to_json`."""
        return cls(
            policy=str(data["policy"]),
            seed=int(data["seed"]),
            requests=int(data["requests"]),
            served=int(data["served"]),
            mean_wait=float(data["mean_wait_s"]),
            mean_wait_second_half=float(data["mean_wait_second_half_s"]),
            empty_km=float(data["empty_km"]),
            driven_km=float(data["driven_km"]),
            fallbacks=int(data["fallbacks"]),
            queued=int(data["queued"]),
            failed=int(data["failed"]),
            sim_seconds=float(data["sim_seconds"]),
            wall_seconds=float(data["wall_seconds"]),
            tripinfo=str(data["tripinfo"]),
            traffic_updates=int(data["traffic_updates"]),
            park_retries=int(data.get("park_retries", 0)),
            lost=int(data.get("lost", 0)),
            waits=[(float(t), float(w), bool(ok)) for t, w, ok in data["waits"]],
            predicted=[(float(t), bool(other)) for t, other in data["predicted"]],
            snapshots=[
                (float(t), {k: (str(v[0]), float(v[1])) for k, v in pos.items()})
                for t, pos in data["snapshots"]
            ],
        )

    def summary(self) -> dict[str, Any]:
        """The headline numbers (no per-request data)."""
        return {
            "policy": self.policy,
            "seed": self.seed,
            "requests": self.requests,
            "served": self.served,
            "mean_wait_s": self.mean_wait,
            "mean_wait_second_half_s": self.mean_wait_second_half,
            "empty_km": self.empty_km,
            "driven_km": self.driven_km,
            "fallbacks": self.fallbacks,
            "queued": self.queued,
            "failed": self.failed,
            "traffic_updates": self.traffic_updates,
            "park_retries": self.park_retries,
            "lost": self.lost,
            "sim_seconds": self.sim_seconds,
            "wall_seconds": self.wall_seconds,
            "sim_speed": self.sim_speed,
        }
