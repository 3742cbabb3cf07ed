"""Reference demand, the optimum it implies, and starting at that optimum.

A fleet may be given a *reference demand* (the true or assumed distribution of
targets). The service then solves the p-median for it once, at creation
(``routing_svc.optimum``: exact MILP for small candidate sets, greedy plus
interchange beyond), stores the optimum in the ``fleet_created`` event, and
reports the gap of the current configuration on ``/metrics`` with the exact
expected cost (no sampling).

For identical vehicles (one type, one speed) serving targets that need any one
of them, the optimum is the p-median. When the fleet has several types or
speeds, or the reference demand carries a requirement mix (``requirements``:
classes of targets, each a multiset of types with a share), it is the
heterogeneous optimum of objective (11) of Le Ny & Pappas
(:mod:`routing_svc.optimum.heterogeneous`): a target is served when the last
required vehicle arrives, in travel time ``d / v``. It is stored with
``"kind": "heterogeneous"`` and the optimal position of every vehicle, and the
gap uses the same objective. Fleets stored without ``kind`` are p-median ones.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.demand.spec import network_demand, recipe_from_reference
from routing_svc.errors import InvalidInput
from routing_svc.optimum import candidate_sites, expected_cost, solve_pmedian
from routing_svc.optimum.heterogeneous import (
    RequirementClass,
    heterogeneous_cost,
    heterogeneous_optimum,
    is_heterogeneous,
    requirement_mix,
)
from routing_svc.service.networks import NetworkEntry
from routing_svc.service.schemas import DemandSpec
from routing_svc.types import NetPosition

if TYPE_CHECKING:
    from routing_svc.service.runtime import FleetRuntime

MAX_SITES = 1500
"""Candidate sites kept for the optimum (subsampled deterministically beyond)."""


def build_demand(entry: NetworkEntry, spec: dict[str, Any]) -> DemandDistribution[NetPosition]:
    """The reference demand of a fleet from its stored spec
    (:func:`routing_svc.demand.spec.recipe_from_reference`)."""
    recipe = recipe_from_reference(spec)
    rng = np.random.default_rng(int(spec.get("seed", 0)))
    return network_demand(entry.network, recipe, rng=rng)


def solve_reference(
    entry: NetworkEntry,
    *,
    cost: str,
    demand: DemandDistribution[NetPosition],
    vehicles: int,
    power: float,
) -> tuple[list[NetPosition], dict[str, Any]]:
    """The p-median (power 1) or p-power-median of ``demand`` with ``vehicles`` sites."""
    space = entry.space(cost)
    sites = candidate_sites(entry.network, demand, max_sites=MAX_SITES)
    if len(sites) < vehicles:
        raise InvalidInput(f"only {len(sites)} candidate sites for {vehicles} vehicles")
    matrix = space.cost_matrix(list(sites), list(demand.positions)) ** power
    solution = solve_pmedian(matrix, np.asarray(demand.weights), vehicles)
    chosen = [sites[i] for i in solution.sites]
    return chosen, {
        "objective": solution.objective,
        "method": solution.method,
        "proven_optimal": solution.proven_optimal,
        "seconds": solution.seconds,
        "sites": len(sites),
    }


def requirement_classes(spec: dict[str, Any]) -> tuple[RequirementClass, ...] | None:
    """The requirement mix of a stored reference demand spec (``None``: any one vehicle)."""
    items = spec.get("requirements")
    if items is None:
        return None
    return tuple(RequirementClass(tuple(i["requires"]), float(i["share"])) for i in items)


def check_mix(spec: dict[str, Any], vehicle_types: Sequence[str]) -> None:
    """Reject a mix with bad shares or types the fleet lacks (before any solving)."""
    requirement_mix(requirement_classes(spec), vehicle_types)


def reference_optimum(
    entry: NetworkEntry,
    *,
    cost: str,
    spec: dict[str, Any],
    demand: DemandDistribution[NetPosition],
    types: Sequence[str],
    speeds: Sequence[float],
    power: float,
) -> dict[str, Any]:
    """The stored optimum: the p-median for identical vehicles that any one serves,
    else the heterogeneous optimum with every vehicle's position."""
    mix = requirement_classes(spec)
    if not is_heterogeneous(types, speeds, mix):
        return solve_reference(entry, cost=cost, demand=demand, vehicles=len(types), power=power)[1]
    space = entry.space(cost)
    sites = candidate_sites(entry.network, demand, max_sites=MAX_SITES)
    positions, solution = heterogeneous_optimum(
        space, sites, demand, types, speeds, mix, power=power
    )
    return {
        "kind": "heterogeneous",
        "objective": solution.objective,
        "method": solution.method,
        "proven_optimal": solution.proven_optimal,
        "seconds": solution.seconds,
        "sites": len(sites),
        "positions": [space.encode(p) for p in positions],
    }


def optimum_start(
    entry: NetworkEntry, *, cost: str, sample: Sequence[NetPosition], vehicles: int, power: float
) -> list[NetPosition]:
    """Starting positions at the p-median of a prior demand sample (equal weights)."""
    demand = DemandDistribution.from_masses("prior-sample", tuple(sample), np.ones(len(sample)))
    positions, _ = solve_reference(entry, cost=cost, demand=demand, vehicles=vehicles, power=power)
    return positions


def expected_cost_now(runtime: FleetRuntime) -> float:
    """Exact expected cost of the fleet's current positions under its reference demand."""
    assert runtime.reference is not None
    demand = runtime.reference_distribution()
    fleet = runtime.fleet
    if runtime.reference["optimum"].get("kind") == "heterogeneous":
        return heterogeneous_cost(
            runtime.entry.space(runtime.cost_kind),
            fleet.state.positions,
            [v.type for v in fleet.vehicles],
            [v.speed for v in fleet.vehicles],
            demand,
            requirement_classes(runtime.reference["demand"]),
            power=fleet.config.objective.power,
        )
    return expected_cost(
        runtime.entry.space(runtime.cost_kind),
        fleet.state.positions,
        np.ones(len(fleet.vehicles)),
        demand,
        power=fleet.config.objective.power,
    )


def describe_spec(spec: DemandSpec) -> dict[str, Any]:
    """The stored form of a reference demand spec."""
    return spec.model_dump(exclude_none=True)
