"""From a ``POST /v1/fleets`` body to the ``fleet_created`` event payload.

Everything that needs a choice is decided here, once, and stored: snapped
starting positions, the learning rule with its defaults (derived from the
network's typical trip cost, see :func:`routing_svc.sa.learning_config`), the
optimum start with the step counters it implies
(:func:`routing_svc.sa.prior_counts`) and the reference optimum. Replay then
needs none of it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

from routing_svc.demand import DemandDistribution
from routing_svc.errors import InvalidInput, RoutingSvcError
from routing_svc.network import RoadSpace
from routing_svc.network.stands import Stand, stands_on_network
from routing_svc.optimum.stands import solve_stands
from routing_svc.sa import Annealing, Objective, learning_config, prior_counts
from routing_svc.sa.consolidation import ConsolidationJob, ConsolidationPolicy, partners_of
from routing_svc.sa.fleet import type_groups
from routing_svc.sa.requirements import build_requirement
from routing_svc.sa.schedules import Counting, schedule_from_dict
from routing_svc.sa.stands import StandSet
from routing_svc.service.networks import NetworkEntry
from routing_svc.service.reference import (
    build_demand,
    check_mix,
    describe_spec,
    reference_optimum,
    solve_reference,
)
from routing_svc.service.schemas import FleetSpec, StandSpec, VehicleSpec
from routing_svc.types import NetPosition

StartGroup = tuple[list[VehicleSpec], list[NetPosition], list[tuple[str, ...]]]
"""Vehicles that start together, the sample targets they start at the optimum of, and
per target the other types it needed (:attr:`routing_svc.sa.Learning.partners`)."""


def start_groups(
    ordered: list[VehicleSpec],
    sample: list[NetPosition],
    requires: Sequence[Sequence[str] | None] | None,
    *,
    per_type: bool,
) -> list[StartGroup]:
    """The vehicles (in id order) that start together at the optimum of a sample, each
    group with the sample's targets it starts at the optimum of.

    Each type apart when there are several, each of one speed, and ``per_type`` (no
    stands, whose capacities the types would share): for targets that each need one
    vehicle of a type, the optimum of objective (11) is each type's p-median of the
    targets that needed it (where such a fleet's consolidations lead,
    :attr:`routing_svc.sa.Fleet.learns_per_type`). A type's targets are those whose
    ``requires`` name it and those that needed any one vehicle (all of them, with no
    partners, when ``requires`` is ``None``); a type no target needed takes the whole
    sample. Else the whole fleet at the p-median of the whole sample, which serves
    targets that need any one vehicle.
    """
    groups = type_groups([v.type for v in ordered], [v.speed for v in ordered])
    if not per_type or groups is None or len(groups) == 1:
        return [(ordered, sample, [() for _ in sample])]
    out: list[StartGroup] = []
    for kind, members in groups.items():
        own = (
            [
                (z, partners_of(kind, needs))
                for z, needs in zip(sample, requires, strict=True)
                if not needs or kind in needs
            ]
            if requires is not None
            else []
        )
        if not own:  # no requires, or none for this type: the whole sample, unpriced
            own = [(z, ()) for z in sample]
        out.append(([ordered[i] for i in members], [z for z, _ in own], [k for _, k in own]))
    return out


def fitted_together(
    space: RoadSpace,
    groups: list[StartGroup],
    starts: dict[str, NetPosition],
    *,
    power: float,
) -> None:
    """Refit, in order, each type whose sample targets needed other types or any one
    vehicle, where a consolidation of its sample would put it with the other types
    standing at their ``starts`` (objective (11) with them fixed:
    :meth:`routing_svc.sa.ConsolidationJob.solve`, a refit taken untested); ``starts``
    is updated in place."""
    policy = ConsolidationPolicy()
    for group, own, partners in groups:
        if not any(partners) or len(own) < 2:  # nothing to price, or no sample to fit
            continue
        others = tuple(
            (g[0].type, tuple(starts[v.id] for v in g), float(g[0].speed))
            for g, _, _ in groups
            if g is not group
        )
        job = ConsolidationJob(
            key=(0, 0, 0), apply_by=0, space=space,
            positions=tuple(starts[v.id] for v in group),
            anchor=tuple(starts[v.id] for v in group), reservoir=tuple(own),
            power=power, speed=float(group[0].speed), confidence=policy.confidence,
            updates=tuple(0 for _ in group), fresh=len(own), folds=policy.folds,
            refit=True, tested_refit=False, stands=None, shakes=policy.shakes,
            partners=tuple(partners), others=others,
        )  # fmt: skip
        starts.update({v.id: p for v, p in zip(group, job.solve().positions, strict=True)})


def check_sample_requires(
    requires: Sequence[Sequence[str] | None] | None, types: Sequence[str]
) -> None:
    """Refuse a sample target that needs a type the fleet lacks, or more vehicles of a
    type than it has (:func:`routing_svc.sa.requirements.build_requirement`)."""
    for i, needs in enumerate(requires or ()):
        if needs:
            try:
                build_requirement(types, needs)
            except RoutingSvcError as exc:
                raise InvalidInput(f"start.optimum.requires[{i}]: {exc.detail}") from None


def build_created_payload(spec: FleetSpec, entry: NetworkEntry) -> dict[str, Any]:
    """Validate a fleet spec against its network and fix every derived value."""
    objective = Objective.parse(spec.objective)
    space = entry.space(spec.cost)
    n = len(spec.vehicles)
    types = [v.type for v in spec.vehicles]
    demand_spec = None if spec.reference_demand is None else describe_spec(spec.reference_demand)
    if demand_spec is not None:
        check_mix(demand_spec, types)
    missing = [v.id for v in spec.vehicles if v.position is None]
    if spec.start is None and missing:
        more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
        named = ", ".join(missing[:5]) + more
        raise InvalidInput(
            f"{len(missing)} of {n} vehicles have no position ({named}); give every vehicle "
            "a position, or none and start from the optimum of a sample"
        )
    if spec.start is not None and len(missing) != n:
        raise InvalidInput("with 'start', leave every vehicle's position out")
    stands = None if spec.stands is None else build_stands(spec.stands, entry, vehicles=n)
    if spec.start is not None:
        optimum_start = spec.start.optimum
        check_sample_requires(optimum_start.requires, types)
        sample = [entry.resolve(p) for p in optimum_start.sample]
        ordered = sorted(spec.vehicles, key=lambda v: v.id)
        starts, served = {}, {}
        groups = start_groups(ordered, sample, optimum_start.requires, per_type=stands is None)
        for group, own, _ in groups:
            prior = DemandDistribution.of_targets("prior-sample", own)
            if stands is None:
                positions, _ = solve_reference(
                    entry, cost=spec.cost, demand=prior, vehicles=len(group), power=objective.power
                )
            else:
                positions = solve_stands(
                    space, prior, len(group), stands, power=objective.power
                ).positions
            # deterministic pairing: vehicles in id order take the sites in edge order
            positions.sort()
            starts.update({v.id: p for v, p in zip(group, positions, strict=True)})
        if len(groups) > 1:
            fitted_together(space, groups, starts, power=objective.power)
        for group, own, _ in groups:
            group_counts = prior_counts(
                space, [starts[v.id] for v in group], [v.speed for v in group], own
            )
            served.update({v.id: k for v, k in zip(group, group_counts, strict=True)})
        counts = tuple(served[v.id] for v in ordered)
    else:
        starts = {v.id: entry.resolve(v.position) for v in spec.vehicles if v.position}
        counts = ()
    rule = spec.learning_rule()
    config = learning_config(
        rule,
        typical_cost=space.typical_cost(),
        n_vehicles=n,
        objective=objective,
        seed=spec.seed,
        schedule=None if spec.step is None else schedule_from_dict(spec.step.to_dict()),
        counting=Counting(spec.counting),
        annealing=None
        if spec.annealing is None
        else Annealing(spec.annealing.scale, spec.annealing.decay),
        probe=None if rule == "paper" and spec.probe == 0.0 else spec.probe,
        prior_counts=counts,
        learning_vehicles=spec.learning_vehicles,
    )
    if stands is not None:
        config = replace(config, stands=stands)
    reference = None
    if demand_spec is not None:
        demand = build_demand(entry, demand_spec)
        optimum = reference_optimum(
            entry,
            cost=spec.cost,
            spec=demand_spec,
            demand=demand,
            types=types,
            speeds=[v.speed for v in spec.vehicles],
            power=objective.power,
            stands=stands,
        )
        reference = {"demand": demand_spec, "optimum": optimum}
    return {
        "network": entry.id,
        "cost": spec.cost,
        "config": config.to_dict(space.encode),
        "vehicles": [
            {"id": v.id, "type": v.type, "speed": v.speed, "position": space.encode(starts[v.id])}
            for v in spec.vehicles
        ],
        "reference": reference,
        "service_thresholds": list(spec.service_thresholds),
    }


def build_stands(
    specs: list[StandSpec], entry: NetworkEntry, *, vehicles: int
) -> StandSet[NetPosition]:
    """The stands of a fleet spec: every one on the network, together holding the fleet.

    Stands at one position add their capacities (:meth:`StandSet.merged`).
    """
    given = [Stand(f"#{i}", s.edge, s.offset, s.capacity) for i, s in enumerate(specs)]
    reading = stands_on_network(given, entry.network)
    if reading.dropped:
        off = "; ".join(f"stand {d.id} on edge {d.edge!r}: {d.reason}" for d in reading.dropped[:5])
        raise InvalidInput(
            f"{len(reading.dropped)} stands are unusable on network {entry.id!r}: {off}"
        )
    stands = reading.stand_set(entry.network)
    stands.check_fleet(vehicles)
    return stands
