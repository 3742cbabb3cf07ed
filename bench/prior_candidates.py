"""How well a fleet started at the p-median of a sample serves the demand, by candidate sites.

A fleet created at the optimum of a sample (``simulate --start prior:N``, a fleet
created from a history, the co-simulation's ``sa`` start) stands at the p-median of
the sample's empirical distribution, eq. (10) of Le Ny & Pappas on ``N`` targets,
over candidate sites. Three rules for those sites are compared on the *demand* the
sample came from (exact expected cost, gap to the demand's optimum):

- ``default``: the service's, ``candidate_sites`` of the sample (its places, then
  edge ends, at most ``MAX_SITES``);
- ``ends``: edge ends only (at most ``MAX_SITES``, evenly spaced in edge order); a
  site at a sampled place serves that place at no cost, so the sample's own places
  may fit its noise;
- ``cross_validated``: whichever of the two serves held-out targets better, five
  folds of the sample (each fold's p-median solved without it, priced on it).

The baseline is ``default``, measured in the same run on the same samples.

Run: ``python bench/prior_candidates.py`` (seven networks, 8 and 20 vehicles, three
hotspots and uniform demand, samples of 300 and 1,000, seeds 0-2) or, e.g.,
``python bench/prior_candidates.py --nets drt --vehicles 8 --seeds 0``.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np
from bench_shared import (
    NETWORKS,
    finished,
    medians_over_seeds,
    refuse_unknown,
    worst_and_mean_by_size,
)
from learning import gap, instance, refuse_degenerate

from routing_svc.demand import DemandDistribution
from routing_svc.network import RoadSpace
from routing_svc.optimum import MAX_SITES, candidate_sites, solve_demand
from routing_svc.sim.command import parse_seeds
from routing_svc.types import NetPosition

RULES = ("default", "ends", "cross_validated")
FOLDS = 5


def edge_ends(space: RoadSpace) -> list[NetPosition]:
    """The end of every edge, at most ``MAX_SITES`` of them evenly spaced in edge order
    (``candidate_sites`` of a distribution whose atoms are the ends)."""
    network = space.network
    ends = [NetPosition(e, float(network.length[e])) for e in range(network.n_edges)]
    as_demand = DemandDistribution.from_masses("ends", ends, np.ones(len(ends)))
    return candidate_sites(network, as_demand, max_sites=MAX_SITES)


def fitted(space: RoadSpace, sample: list[NetPosition], n: int, rule: str) -> list[NetPosition]:
    """The p-median of ``sample`` over the candidate sites of ``rule``."""
    sites = None if rule == "default" else edge_ends(space)
    demand = DemandDistribution.of_targets("sample", sample)
    return solve_demand(space, demand, n, sites=sites, method="heuristic").positions


def held_out_costs(space: RoadSpace, sample: list[NetPosition], n: int) -> dict[str, float]:
    """Each rule's total cost on every target, from the fit of the folds without it."""
    total = {"default": 0.0, "ends": 0.0}
    for fold in range(FOLDS):
        train = [z for i, z in enumerate(sample) if i % FOLDS != fold]
        test = [z for i, z in enumerate(sample) if i % FOLDS == fold]
        for rule in total:
            costs = space.cost_matrix(fitted(space, train, n, rule), test)
            total[rule] += float(costs.min(axis=0).sum())
    return total


def job(net: str, n: int, demand: str, size: int, seed: int) -> dict[str, Any]:
    inst = instance(net, n, seed, demand)
    refuse_degenerate(inst, net, n)
    sample = inst.demand.sample(np.random.default_rng([seed, 9, size]), size)
    gaps = {
        rule: gap(inst.space, fitted(inst.space, sample, n, rule), inst.demand, inst.optimum[0])
        for rule in ("default", "ends")
    }
    held_out = held_out_costs(inst.space, sample, n)
    choice = min(held_out, key=lambda rule: held_out[rule])
    gaps["cross_validated"] = gaps[choice]
    return {
        "network": net,
        "vehicles": n,
        "demand": demand,
        "sample": size,
        "seed": seed,
        "gaps": gaps,
        "cross_validated_choice": choice,
    }


def summarise(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians over seeds per case; per sample size, the mean and the worst of them."""
    medians = medians_over_seeds(
        records, lambda r: f"{r['network']}/{r['vehicles']}/{r['demand']}/{r['sample']}", RULES
    )
    by_size = worst_and_mean_by_size(medians, (r["sample"] for r in records), RULES)
    for summary in by_size.values():
        default = summary["default"]["mean_of_medians"]
        for rule in RULES:
            summary[rule]["ratio_to_default"] = summary[rule]["mean_of_medians"] / default
    return {"median_over_seeds": medians, "by_sample_size": by_size}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--nets", default=",".join(NETWORKS))
    p.add_argument("--vehicles", type=parse_seeds, default="8,20")
    p.add_argument("--demands", default="hotspots:3,uniform")
    p.add_argument("--samples", type=parse_seeds, default="300,1000")
    p.add_argument("--seeds", type=parse_seeds, default="0,1,2")
    args = p.parse_args()
    refuse_unknown(p, args.nets.split(","), args.demands.split(","))
    if min(args.vehicles) < 1:
        p.error("--vehicles: a fleet has at least one vehicle")
    if min(args.samples) < max(args.vehicles):
        p.error("every sample must hold at least as many targets as the largest fleet")
    started = time.perf_counter()
    records = [
        job(net, n, demand, size, seed)
        for net in args.nets.split(",")
        for n in args.vehicles
        for demand in args.demands.split(",")
        for size in args.samples
        for seed in args.seeds
    ]
    report = {
        "benchmark": "prior_candidates",
        "baseline": "default (the service's candidate sites of a sample)",
        "gap": "exact expected cost on the demand, relative to its optimum",
        **summarise(records),
    }
    print(json.dumps(finished(report, records, started), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
