"""Gradual drift: how far a fleet stays behind hotspots that move slowly, and after.

The demand of ``bench/learning.py`` (three hotspots drawn from the seed) stays for
``--settle`` targets; then its centres move in a straight line to the shifted
demand's centres (the ``shift`` scenario's) over ``--drift`` targets, in stages
of :data:`STAGE` targets each drawn from the demand of its stage; then the demand
stays there for ``--hold`` targets. At the checkpoints the fleet's exact expected
cost is compared with the best p-median of the demand of that moment (its gap).

The named baseline, in the same run on the same targets, is the batch answer of
the recent targets: the p-median of the last ``W`` targets for ``W`` = 2,000 and
4,000 (the consolidating rule's reservoir), which a drift leaves behind by about
``W / 2`` targets. Rules: the default ``consolidating`` and ``probe``. Medians over
seeds; the worst network counts.

Run: ``python bench/drift.py`` (seven networks, 8 and 20 vehicles, seeds 0-2) or,
e.g., ``python bench/drift.py --nets drt --vehicles 20 --seeds 0``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from bench_shared import NETWORKS, finished, network_name, refuse_unknown
from learning import gap, instance, refuse_degenerate

from routing_svc.demand import DemandDistribution
from routing_svc.demand import network as network_demand
from routing_svc.network import CompiledNetwork
from routing_svc.optimum import solve_demand
from routing_svc.sa import Fleet, Objective, Vehicle, learning_config
from routing_svc.sim.command import parse_seeds
from routing_svc.types import FloatArray, NetPosition

STAGE = 500
"""Targets drawn from one stage of the drift."""

HOTSPOTS = 3
WINDOWS = (2000, 4000)
RULES = ("consolidating", "probe")

Job = tuple[str, int, int, int, int, int]


def centres(network: CompiledNetwork, seed: list[int]) -> FloatArray:
    """The hotspot centres ``network_demand`` draws for ``hotspots:3`` with this seed."""
    edges, offsets, pieces = network_demand.edge_pieces(
        network, spacing=network_demand.DEFAULT_SPACING
    )
    xy = network_demand.positions_xy(network, edges, offsets)
    rng = np.random.default_rng(seed)
    picks = rng.choice(len(pieces), size=HOTSPOTS, replace=False, p=pieces / pieces.sum())
    return np.asarray(xy[picks], dtype=np.float64)


def hotspots_at(network: CompiledNetwork, at: FloatArray) -> DemandDistribution[NetPosition]:
    return network_demand.hotspot_mixture(network, centres=[(float(x), float(y)) for x, y in at])


def checkpoints(settle: int, drift: int, hold: int) -> dict[int, str]:
    """Targets seen -> label: the end of the settling, four points of the drift, and
    1,000, 5,000 and ``hold`` targets after it (as many as ``hold`` allows)."""
    marks = {settle: "settled"}
    marks |= {settle + drift * q // 4: f"drift {q}/4" for q in (1, 2, 3, 4)}
    marks |= {settle + drift + k: f"+{k}" for k in (1000, 5000, hold) if k <= hold}
    return marks


def job(args: Job) -> dict[str, Any]:
    net, n, seed, settle, drift, hold = args
    t0 = time.perf_counter()
    inst = instance(net, n, seed)
    refuse_degenerate(inst, net, n)
    space, network = inst.space, inst.space.network
    start, end = centres(network, [seed, 0]), centres(network, [seed, 2])
    for at, demand in ((start, inst.demand), (end, inst.shifted)):
        same = hotspots_at(network, at).weights
        if not np.array_equal(np.asarray(same), np.asarray(demand.weights)):
            raise AssertionError("the drift must go from bench/learning.py's demand to its shift")
    stages = drift // STAGE
    rng = np.random.default_rng([seed, 1])
    stream: list[NetPosition] = inst.demand.sample(rng, settle)
    demand_of: dict[int, DemandDistribution[NetPosition]] = {}
    for s in range(1, stages + 1):
        at = start + (end - start) * s / stages if s < stages else end
        demand_of[settle + s * STAGE] = hotspots_at(network, at)
        stream += demand_of[settle + s * STAGE].sample(rng, STAGE)
    stream += inst.shifted.sample(rng, hold)
    marks = checkpoints(settle, drift, hold)

    def demand_at(k: int) -> DemandDistribution[NetPosition]:
        if k <= settle:
            return inst.demand
        if k >= settle + drift:
            return inst.shifted
        return demand_of[settle + ((k - settle + STAGE - 1) // STAGE) * STAGE]

    optimum = {k: solve_demand(space, demand_at(k), n).objective for k in marks}
    record: dict[str, Any] = {"network": network_name(net), "vehicles": n, "seed": seed}
    for w in WINDOWS:
        record[f"recent_{w}"] = {
            label: gap(
                space,
                solve_demand(
                    space,
                    DemandDistribution.of_targets("recent", stream[max(0, k - w) : k]),
                    n,
                    method="heuristic",
                ).positions,
                demand_at(k),
                optimum[k],
            )
            for k, label in marks.items()
        }
    for rule in RULES:
        config = learning_config(
            rule,
            typical_cost=space.typical_cost(),
            n_vehicles=n,
            objective=Objective(1.0),
            seed=seed,
        )
        vehicles = [(Vehicle(f"v{i:03d}"), p) for i, p in enumerate(inst.random_start)]
        fleet = Fleet.create(space, vehicles, config)
        gaps = {}
        for k, z in enumerate(stream, start=1):
            fleet.observe(z)
            if k in marks:
                gaps[marks[k]] = gap(space, fleet.state.positions, demand_at(k), optimum[k])
        record[rule] = gaps
    record["seconds"] = time.perf_counter() - t0
    print(f"{record['network']} n={n} seed={seed}: {record['seconds']:.0f} s", file=sys.stderr)
    return record


def summarise(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians over seeds per network and size; per checkpoint, the worst of them."""
    answers = (*RULES, *(f"recent_{w}" for w in WINDOWS))
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in records:
        groups.setdefault(f"{r['network']}/{r['vehicles']}", []).append(r)
    table = {
        key: {
            a: {label: statistics.median(r[a][label] for r in rs) for label in rs[0][a]}
            for a in answers
        }
        for key, rs in sorted(groups.items())
    }
    labels = list(records[0][RULES[0]])
    worst = {
        a: {label: max((e[a][label], key) for key, e in table.items()) for label in labels}
        for a in answers
    }
    during = [label for label in labels if label.startswith("drift")]
    return {
        "median_over_seeds": table,
        "worst_network": worst,
        "worst_during_drift": {
            a: max((e[a][label], f"{key}@{label}") for key, e in table.items() for label in during)
            for a in answers
        },
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--nets", default=",".join(NETWORKS))
    p.add_argument("--vehicles", type=parse_seeds, default="8,20")
    p.add_argument("--seeds", type=parse_seeds, default="0,1,2")
    p.add_argument("--settle", type=int, default=10_000)
    p.add_argument("--drift", type=int, default=20_000)
    p.add_argument("--hold", type=int, default=10_000)
    p.add_argument("--jobs", type=int, default=2)
    args = p.parse_args()
    refuse_unknown(p, args.nets.split(","))
    if args.drift < 4 * STAGE or args.drift % (4 * STAGE):
        p.error(f"--drift must be a positive multiple of {4 * STAGE}")
    if args.settle < 1 or args.hold < 1 or args.jobs < 1:
        p.error("--settle, --hold and --jobs must be at least 1")
    started = time.perf_counter()
    jobs: list[Job] = [
        (net, n, seed, args.settle, args.drift, args.hold)
        for net in args.nets.split(",")
        for n in args.vehicles
        for seed in args.seeds
    ]
    with ProcessPoolExecutor(args.jobs) as pool:
        records = list(pool.map(job, jobs))
    report = {
        "benchmark": "drift",
        "baseline": "recent_4000: the p-median of the last 4,000 targets (the reservoir's size)",
        "gap": "exact expected cost on the demand of the moment, relative to its optimum",
        "settle": args.settle,
        "drift": args.drift,
        "hold": args.hold,
        **summarise(records),
    }
    print(json.dumps(finished(report, records, started), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
