"""What SUMO measured: waits from ``personinfo``, distances from the taxis' ``tripinfo``.

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
from dataclasses import dataclass
from pathlib import Path

from defusedxml import ElementTree

from routing_svc.sim.backend import SimulationError

__all__ = ["FleetDistance", "RideRecord", "TripMeasures", "read_tripinfo"]


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
