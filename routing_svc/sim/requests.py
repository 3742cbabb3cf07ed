"""Request streams of a co-simulation, fixed before any policy runs.

Every policy sees the same requests (same times, places and ride
destinations), so the comparison is fair:

- ``persons``: at the times of a Poisson process, a person appears at a place
  drawn from a demand distribution (weighted atoms on edges: uniform by
  length, a hotspot mixture, given edge weights) and asks for a taxi ride to a
  destination drawn uniformly by length. The distribution may change at given
  times (``phases``: the hotspots move).
- ``incidents``: at the times of a Poisson process, an incident appears where
  a random background vehicle is at that moment. The stream is recorded in a
  SUMO run of the background traffic alone (same seed as the policy runs), so
  the demand follows the traffic and its distribution is not known to anyone;
  each incident is then a person at that place asking for a ride (the same
  reservation and measurement path as ``persons``) to a destination drawn
  the same way (e.g. a nearby garage).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.demand.profile import HourlyProfile
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork
from routing_svc.sim.backend import SimBackend
from routing_svc.sim.inputs import Request
from routing_svc.types import NetPosition

__all__ = ["Destinations", "Phase", "incident_requests", "person_requests", "poisson_times"]


@dataclass(frozen=True, slots=True)
class Phase:
    """A demand distribution that holds from ``start`` (s) until the next phase."""

    start: float
    demand: DemandDistribution[NetPosition]


def poisson_times(
    rng: np.random.Generator, *, rate_per_hour: float, start: float, end: float
) -> list[float]:
    """Arrival times of a Poisson process of ``rate_per_hour`` in ``[start, end)``."""
    if not rate_per_hour > 0.0 or not end >= start:
        raise InvalidInput("the request rate must be > 0 and the end not before the start")
    times: list[float] = []
    t = start
    mean_gap = 3600.0 / rate_per_hour
    while True:
        t += float(rng.exponential(mean_gap))
        if t >= end:
            return times
        times.append(t)


class Destinations:
    """Ride destinations: atoms of a distribution within ``radius`` metres of the origin.

    The straight-line distance between edge midpoints decides; when no atom
    lies that close, any atom on another edge may be drawn.
    """

    def __init__(
        self,
        network: CompiledNetwork,
        demand: DemandDistribution[NetPosition],
        *,
        radius: float,
    ) -> None:
        if not radius > 0.0:
            raise InvalidInput(f"the ride radius must be > 0, got {radius!r}")
        self.network = network
        self.demand = demand
        self.radius = radius
        middle = np.array(
            [
                network.shape_xy[network.shape_offsets[e] : network.shape_offsets[e + 1]].mean(
                    axis=0
                )
                for e in range(network.n_edges)
            ]
        )
        self._edge_xy = middle
        self._edges = np.array([p.edge for p in demand.positions], dtype=np.int64)
        self._atom_xy = middle[self._edges]

    def draw(self, rng: np.random.Generator, origin_edge: int) -> NetPosition:
        """A destination on another edge than ``origin_edge``, near it if possible."""
        gap = np.hypot(*(self._atom_xy - self._edge_xy[origin_edge]).T)
        mask = (self._edges != origin_edge) & (gap <= self.radius)
        if not mask.any():
            mask = self._edges != origin_edge
        if not mask.any():
            mask = np.ones(len(self._edges), dtype=bool)
        weights = np.where(mask, self.demand.weights, 0.0)
        pick = int(rng.choice(len(weights), p=weights / weights.sum()))
        return self.demand.positions[pick]


def _request(
    network: CompiledNetwork, number: int, time: float, origin: NetPosition, to: NetPosition
) -> Request:
    return Request(
        id=f"req{number:06d}",
        time=round(time, 2),
        edge=network.edge_ids[origin.edge],
        offset=round(min(float(origin.offset), float(network.length[origin.edge])), 2),
        to_edge=network.edge_ids[to.edge],
        to_offset=round(min(float(to.offset), float(network.length[to.edge])), 2),
    )


def person_requests(
    network: CompiledNetwork,
    phases: Sequence[Phase],
    destinations: Destinations,
    *,
    rng: np.random.Generator,
    rate_per_hour: float,
    start: float,
    end: float,
    profile: HourlyProfile | None = None,
) -> list[Request]:
    """Persons asking for rides at Poisson times from the active phase's distribution.

    Parameters
    ----------
    network : CompiledNetwork
        The network the distributions' edge indices refer to.
    phases : sequence of Phase
        Sorted by ``start``; the first must start at or before ``start``.
    destinations : Destinations
        Where rides end.
    rng : numpy.random.Generator
        The only source of randomness.
    rate_per_hour, start, end : float
        The Poisson process of request times.
    profile : HourlyProfile, optional
        A time-of-day profile: the rate at ``t`` is ``rate_per_hour * profile.factor(t)``,
        drawn by thinning a stream at the largest rate
        (:mod:`routing_svc.demand.profile`). Without one the rate is constant.
    """
    if not phases or phases[0].start > start:
        raise InvalidInput("the first demand phase must start at or before the first request")
    starts = [p.start for p in phases]
    if starts != sorted(starts):
        raise InvalidInput("demand phases must be sorted by start time")
    requests = []
    top = 1.0 if profile is None else profile.largest_factor
    times = poisson_times(rng, rate_per_hour=rate_per_hour * top, start=start, end=end)
    if profile is not None:
        keep = rng.random(len(times)) * top < [profile.factor(t) for t in times]
        times = [t for t, kept in zip(times, keep, strict=True) if kept]
    for number, t in enumerate(times):
        phase = phases[int(np.searchsorted(starts, t, side="right")) - 1]
        (origin,) = phase.demand.sample(rng, 1)
        to = destinations.draw(rng, origin.edge)
        requests.append(_request(network, number, t, origin, to))
    return requests


def incident_requests(
    backend: SimBackend,
    network: CompiledNetwork,
    destinations: Destinations,
    *,
    rng: np.random.Generator,
    rate_per_hour: float,
    start: float,
    end: float,
) -> list[Request]:
    """Incidents at the places of random background vehicles, at Poisson times.

    ``backend`` must have been started with the background traffic only; it
    is stepped until ``end`` (and left open for the caller to close). An
    incident at time ``t`` takes a vehicle uniformly at random among those on
    an edge of ``network`` at the first step at or after ``t``; if there is
    none, the incident moves to the next step.
    """
    times = poisson_times(rng, rate_per_hour=rate_per_hour, start=start, end=end)
    requests: list[Request] = []
    pending = 0
    while pending < len(times) and backend.time() < end:
        backend.step()
        now = backend.time()
        while pending < len(times) and times[pending] <= now:
            candidates = [
                (network.edge_index[road], position)
                for _, road, position in backend.vehicle_places()
                if road in network.edge_index
            ]
            if not candidates:
                break
            edge, position = candidates[int(rng.integers(len(candidates)))]
            offset = min(max(position, 0.0), float(network.length[edge]))
            origin = NetPosition(edge, offset)
            to = destinations.draw(rng, edge)
            requests.append(_request(network, len(requests), now, origin, to))
            pending += 1
    return requests
