"""What a co-simulation is about, before any policy runs: demand, starts, optimum.

A :class:`Scenario` fixes, for one network, fleet size and seed, everything
that every policy shares: the background traffic file, the request stream
(written as SUMO persons), the start positions (drawn uniformly by road
length), the true demand distribution over time (for ``incidents``: the
empirical distribution of the realised requests), and the p-median of that
distribution (``routing_svc.optimum``), to which the ``optimum`` policy is
frozen and against which the SA objective is plotted.

Seeds: the request stream uses ``numpy.random.default_rng([seed, 1])``, the
start positions ``[seed, 2]``, randomTrips and SUMO ``seed`` itself; the
hotspot layout uses ``[demand_seed, 3]``, so several seeds replicate one
scenario.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.demand.profile import HourlyProfile
from routing_svc.demand.spec import network_demand, parse_demand_spec
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork, RoadSpace
from routing_svc.optimum.solve import solve_demand
from routing_svc.optimum.stands import solve_stands
from routing_svc.sa.stands import StandSet
from routing_svc.sim.inputs import FleetVehicle, Request
from routing_svc.sim.requests import Phase
from routing_svc.types import NetPosition

__all__ = [
    "Optimum",
    "build_demand",
    "demand_at",
    "demand_profile",
    "empirical_demand",
    "fleet_vehicles",
    "mixed_demand",
    "solve_optimum",
    "solve_stand_optimum",
    "start_positions",
]


@dataclass(frozen=True, slots=True)
class Optimum:
    """The p-median of a demand distribution: positions and expected wait (s)."""

    positions: tuple[NetPosition, ...]
    expected_cost: float
    method: str
    proven_optimal: bool


def build_demand(
    network: CompiledNetwork, spec: str, *, rng: np.random.Generator
) -> DemandDistribution[NetPosition]:
    """The distribution of a ``--demand`` spec (:mod:`routing_svc.demand.spec`)."""
    return network_demand(network, parse_demand_spec(spec), rng=rng)


def demand_profile(spec: str) -> HourlyProfile | None:
    """The time-of-day profile of a ``--demand`` spec (``?profile=FILE``), if any."""
    return parse_demand_spec(spec).profile


def start_positions(
    network: CompiledNetwork, vehicles: int, *, rng: np.random.Generator
) -> list[NetPosition]:
    """Distinct random edges, drawn uniformly by length; each vehicle mid-edge."""
    if not 1 <= vehicles <= network.n_edges:
        raise InvalidInput(f"vehicles must be between 1 and {network.n_edges}, got {vehicles}")
    weights = network.length / network.length.sum()
    edges = rng.choice(network.n_edges, size=vehicles, replace=False, p=weights)
    return [NetPosition(int(e), float(network.length[e]) / 2.0) for e in edges]


def fleet_vehicles(
    network: CompiledNetwork, positions: Sequence[NetPosition], *, prefix: str
) -> tuple[FleetVehicle, ...]:
    """Fleet vehicles ``<prefix>000``, ``<prefix>001``, ... at ``positions``."""
    return tuple(
        FleetVehicle(f"{prefix}{i:03d}", network.edge_ids[p.edge], float(p.offset))
        for i, p in enumerate(positions)
    )


def empirical_demand(
    network: CompiledNetwork, requests: Sequence[Request]
) -> DemandDistribution[NetPosition]:
    """The realised requests as a distribution: each place weighted by how many
    requests it had."""
    if not requests:
        raise InvalidInput("no requests to build a distribution from")
    atoms = [NetPosition(network.edge_index[r.edge], float(r.offset)) for r in requests]
    return DemandDistribution.of_targets("realised", atoms)


def mixed_demand(phases: Sequence[Phase], *, end: float) -> DemandDistribution[NetPosition]:
    """The time average of the phases' distributions over ``[phases[0].start, end)``."""
    atoms: list[NetPosition] = []
    masses: list[float] = []
    bounds = [p.start for p in phases[1:]] + [end]
    for phase, stop in zip(phases, bounds, strict=True):
        share = max(stop - phase.start, 0.0)
        atoms.extend(phase.demand.positions)
        masses.extend((share * phase.demand.weights).tolist())
    return DemandDistribution.from_masses("time-average", atoms, masses)


def demand_at(phases: Sequence[Phase], time: float) -> DemandDistribution[NetPosition]:
    """The distribution in force at ``time``."""
    active = phases[0]
    for phase in phases:
        if phase.start <= time:
            active = phase
    return active.demand


def solve_optimum(
    space: RoadSpace, demand: DemandDistribution[NetPosition], vehicles: int
) -> Optimum:
    """The exact or best-known p-median of ``demand`` (routing objective).

    Candidate sites, costs and solver are :func:`routing_svc.optimum.solve.solve_demand`'s
    (at most :data:`~routing_svc.optimum.solve.MAX_SITES` sites; costs are the space's,
    free-flow seconds for ``time``).
    """
    best = solve_demand(space, demand, vehicles)
    positions = tuple(sorted(best.positions))
    return Optimum(positions, best.objective, best.solution.method, best.solution.proven_optimal)


def solve_stand_optimum(
    space: RoadSpace,
    demand: DemandDistribution[NetPosition],
    vehicles: int,
    stands: StandSet[NetPosition],
) -> Optimum:
    """The p-median of ``demand`` over ``stands``, within their capacities
    (:func:`~routing_svc.optimum.stands.solve_stands`; a stand repeated per vehicle it
    holds)."""
    best = solve_stands(space, demand, vehicles, stands)
    positions = tuple(sorted(best.positions))
    return Optimum(
        positions,
        expected_wait(space, positions, demand),
        best.solution.method,
        best.solution.proven_optimal,
    )


def expected_wait(
    space: RoadSpace, positions: Sequence[NetPosition], demand: DemandDistribution[NetPosition]
) -> float:
    """Exact expected free-flow time from the nearest reference position (the SA objective)."""
    from routing_svc.optimum.evaluate import expected_cost

    return expected_cost(space, list(positions), np.ones(len(positions)), demand)
