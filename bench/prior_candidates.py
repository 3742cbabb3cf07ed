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
import statistics
import time
from typing import Any

import numpy as np
from learning import NETWORKS, gap, instance, network_file

from routing_svc.demand import DemandDistribution
from routing_svc.demand.spec import parse_demand_spec
from routing_svc.errors import InvalidInput, UnknownNetwork
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
    cases: dict[str, list[dict[str, Any]]] = {}
    for r in records:
        key = f"{r['network']}/{r['vehicles']}/{r['demand']}/{r['sample']}"
        cases.setdefault(key, []).append(r)
    medians = {
        key: {rule: statistics.median(r["gaps"][rule] for r in rs) for rule in RULES}
        for key, rs in cases.items()
    }
    by_size: dict[str, Any] = {}
    for size in sorted({r["sample"] for r in records}):
        rows = {k: v for k, v in medians.items() if k.endswith(f"/{size}")}
        by_size[str(size)] = {
            rule: {
                "mean_of_medians": statistics.fmean(v[rule] for v in rows.values()),
                "worst": max((v[rule], k) for k, v in rows.items()),
                "ratio_to_default": statistics.fmean(v[rule] for v in rows.values())
                / statistics.fmean(v["default"] for v in rows.values()),
            }
            for rule in RULES
        }
    return {"median_over_seeds": medians, "by_sample_size": by_size}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--nets", default=",".join(NETWORKS))
    p.add_argument("--vehicles", type=parse_seeds, default="8,20")
    p.add_argument("--demands", default="hotspots:3,uniform")
    p.add_argument("--samples", type=parse_seeds, default="300,1000")
    p.add_argument("--seeds", type=parse_seeds, default="0,1,2")
    args = p.parse_args()
    try:
        for net in args.nets.split(","):
            network_file(net)
        for demand in args.demands.split(","):
            parse_demand_spec(demand)
    except (InvalidInput, UnknownNetwork) as e:
        p.error(str(e))
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
        "records": records,
        "seconds": time.perf_counter() - started,
    }
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
