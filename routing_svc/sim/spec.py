"""What a co-simulation experiment simulates: :class:`CosimSpec`.

It is plain, validated data shared by the preparation of the inputs
(:mod:`routing_svc.sim.prepare`) and the experiment that runs the policies
(:mod:`routing_svc.sim.experiment`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from routing_svc.errors import InvalidInput
from routing_svc.sim.dispatcher import QUEUE_ORDERS
from routing_svc.sim.policies import DEFAULT_POLICIES, POLICIES, Policy

__all__ = ["DEFAULT_INCIDENT_SAMPLE", "CosimSpec"]

DEFAULT_INCIDENT_SAMPLE = 2000
"""Incidents recorded apart whose p-median is the ``optimum`` of an ``incidents`` run."""


@dataclass(frozen=True, slots=True, kw_only=True)
class CosimSpec:
    """What to simulate (keyword-only; everything but ``network`` has a default).

    Attributes
    ----------
    network : str
        A network name (``grid``, ``drt``, ...) or a ``.net.xml[.gz]`` path.
    mode : {"persons", "incidents"}
        Where requests come from (see :mod:`routing_svc.sim.requests`).
    vehicles : int
        Fleet size.
    duration : float
        Simulated seconds during which requests are made.
    warmup : float
        Seconds of background traffic before the first request.
    drain : float
        Seconds simulated after the last request (to serve it).
    rate : float
        Requests per hour.
    demand : str
        ``persons``: ``uniform``, ``hotspots[:K]`` or an edge-weights file.
    demand_seed : int
        Seed of the hotspot layout (shared by all seeds).
    shift_at : float, optional
        ``persons``: seconds after the first request when the hotspots move.
    ride_radius : float
        Rides end within this straight-line distance (m) of the request, if possible.
    history : int
        Historical requests that ``sa`` and ``sa-floor`` learn from before the run.
    incident_sample : int
        ``incidents``: incidents recorded in the same background-only run, apart
        from the evaluation stream, whose p-median is the ``optimum``'s references
        (an estimate of the incident distribution, not the realised requests).
    density : float
        Background traffic: randomTrips' insertion density (vehicles per hour
        and km of road).
    traffic_period : float, optional
        Push SUMO's edge travel times to the fleet every this many seconds.
    cost : {"time", "length"}
        The fleet's cost (``time``: free-flow, or live with ``traffic_period``).
    policies : tuple of Policy
        What to compare.
    seeds : tuple of int
        One replication per seed.
    service_url : str, optional
        A running service instead of the in-process one.
    backend : {"libsumo", "traci"}
        How to run SUMO; ``gui`` implies traci.
    gui : bool
        Show ``sumo-gui`` (runs one at a time).
    workers : int
        Parallel SUMO processes.
    snapshot_period : float
        Seconds between records of the reference positions.
    rule : str, optional
        The learning rule of the service's fleets (``consolidating``, ``probe`` or
        ``paper``; ``None``: the service's default).
    stands : str, optional
        A SUMO additional file whose usable ``parkingArea`` elements are the
        stands (:func:`~routing_svc.network.stands.usable_stands`): the service's
        fleets are restricted to them and park in them when idle, the
        ``optimum`` is solved over them, and ``sumo-taxistand`` uses them.
    move_up : bool
        The service's idle vehicles wait at the posts it names (``GET .../posts``)
        instead of their own references (every policy the service dispatches; not
        with ``stands``); ``False``: each at its own reference.
    queue_order : {"soonest", "fifo"}
        Which waiting request the service's vehicles serve next when they become
        available (:meth:`routing_svc.sim.dispatcher.FleetDispatcher._next_waiting`).
    """

    network: str
    mode: Literal["persons", "incidents"] = "persons"
    vehicles: int = 10
    duration: float = 7200.0
    warmup: float = 600.0
    drain: float = 900.0
    rate: float = 60.0
    demand: str = "hotspots:3"
    demand_seed: int = 1
    shift_at: float | None = None
    ride_radius: float = 1500.0
    history: int = 0
    incident_sample: int = DEFAULT_INCIDENT_SAMPLE
    density: float = 10.0
    traffic_period: float | None = None
    cost: Literal["time", "length"] = "time"
    policies: tuple[Policy, ...] = tuple(POLICIES[n] for n in DEFAULT_POLICIES)
    seeds: tuple[int, ...] = (0,)
    service_url: str | None = None
    backend: str = "libsumo"
    gui: bool = False
    workers: int = 2
    snapshot_period: float = 300.0
    rule: str | None = None
    stands: str | None = None
    move_up: bool = True
    queue_order: str = "soonest"

    def __post_init__(self) -> None:
        if self.mode not in ("persons", "incidents"):
            raise InvalidInput(f"mode must be 'persons' or 'incidents', got {self.mode!r}")
        if self.vehicles < 1 or not self.seeds or not self.policies or self.workers < 1:
            raise InvalidInput("need >= 1 vehicle, seed, policy and worker")
        if self.queue_order not in QUEUE_ORDERS:
            raise InvalidInput(f"queue_order must be one of {QUEUE_ORDERS}: {self.queue_order!r}")
        if self.history < 0:
            raise InvalidInput("history must be >= 0")
        if self.incident_sample < 1:
            raise InvalidInput("incident_sample must be >= 1")
        for name in ("duration", "rate", "density", "ride_radius"):
            if not math.isfinite(getattr(self, name)) or getattr(self, name) <= 0.0:
                raise InvalidInput(f"{name} must be a finite number > 0")
        if self.warmup < 0.0 or self.drain < 0.0:
            raise InvalidInput("warmup and drain must be >= 0")
        if self.shift_at is not None and not 0.0 < self.shift_at < self.duration:
            raise InvalidInput("shift_at must lie inside the request period")
        if self.mode == "incidents" and self.shift_at is not None:
            raise InvalidInput("shift_at applies to persons only")
        if self.traffic_period is not None and (
            self.cost != "time" or not self.traffic_period > 0.0
        ):
            raise InvalidInput("traffic_period needs cost 'time' and a period > 0")

    @property
    def end(self) -> float:
        """The simulation's last second."""
        return self.warmup + self.duration + self.drain

    def to_dict(self) -> dict[str, Any]:
        data = {k: getattr(self, k) for k in self.__dataclass_fields__}
        data["policies"] = [p.name for p in self.policies]
        data["seeds"] = list(self.seeds)
        return data
