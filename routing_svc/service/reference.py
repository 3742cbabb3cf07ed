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
gap uses the same objective. A fleet of identical vehicles with stands has the
optimum over its stands (``"kind": "stands"``, :func:`routing_svc.optimum.stands.solve_stands`),
and its gap is that of the stands where its vehicles wait. Fleets stored without
``kind`` are p-median ones.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.demand.spec import network_demand, recipe_from_reference
from routing_svc.optimum import MAX_SITES, candidate_sites, expected_cost, solve_demand
from routing_svc.optimum.heterogeneous import (
    RequirementClass,
    heterogeneous_cost,
    heterogeneous_optimum,
    is_heterogeneous,
    requirement_mix,
)
from routing_svc.optimum.stands import solve_stands
from routing_svc.sa import Fleet
from routing_svc.sa.stands import StandSet
from routing_svc.service.networks import NetworkEntry
from routing_svc.service.schemas import DemandSpec
from routing_svc.types import NetPosition


class ReferencedFleet(Protocol):
    """What :func:`expected_cost_now` reads of a fleet's runtime
    (:class:`routing_svc.service.runtime.FleetRuntime`, which imports this module)."""

    @property
    def entry(self) -> NetworkEntry: ...

    @property
    def cost_kind(self) -> str: ...

    @property
    def fleet(self) -> Fleet[NetPosition]: ...

    @property
    def reference(self) -> dict[str, Any] | None: ...

    def reference_distribution(self) -> DemandDistribution[NetPosition]: ...


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
    best = solve_demand(entry.space(cost), demand, vehicles, power=power)
    return best.positions, {
        "objective": best.objective,
        "method": best.solution.method,
        "proven_optimal": best.solution.proven_optimal,
        "seconds": best.solution.seconds,
        "sites": len(best.sites),
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
    stands: StandSet[NetPosition] | None = None,
) -> dict[str, Any]:
    """The stored optimum: the p-median for identical vehicles that any one serves (over
    the fleet's ``stands``, if it has any: kind ``stands``), else the heterogeneous
    optimum with every vehicle's position."""
    mix = requirement_classes(spec)
    if not is_heterogeneous(types, speeds, mix):
        if stands is not None:
            best = solve_stands(entry.space(cost), demand, len(types), stands, power=power)
            return {
                "kind": "stands",
                "objective": best.objective,
                "method": best.solution.method,
                "proven_optimal": best.solution.proven_optimal,
                "seconds": best.solution.seconds,
                "sites": len(best.sites),
            }
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


def expected_cost_now(runtime: ReferencedFleet) -> float:
    """Exact expected cost of the fleet's current positions under its reference demand
    (of its stands, where a fleet with stands waits)."""
    assert runtime.reference is not None
    demand = runtime.reference_distribution()
    fleet = runtime.fleet
    if runtime.reference["optimum"].get("kind") == "stands":
        return expected_cost(
            runtime.entry.space(runtime.cost_kind),
            list(fleet.stands().values()),
            np.ones(len(fleet.vehicles)),
            demand,
            power=fleet.config.objective.power,
        )
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
