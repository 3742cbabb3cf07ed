"""Learning with vehicles of two types: how far each rule stays from the optimum of objective (11).

Half the fleet is of type ``A``, half of type ``B`` (one speed). Each target of the
three-hotspot demand of ``bench/learning.py`` needs one vehicle of type ``A`` or one of
type ``B``, with equal chance wherever it appears (``--mix one-of-two``, the default), or
needs one A, one B, or an A and a B, a third each (``--mix thirds``; the last arrival
serves it). With one type a target, objective (11) is the sum of two p-medians, one per
type on the whole demand: the optimum is the best p-median of the demand for ``n / 2``
vehicles. With ``thirds`` it is the best found by the heterogeneous solver's local search
over the same candidate sites. A fleet's gap is its exact expected cost
(:func:`~routing_svc.optimum.heterogeneous.heterogeneous_cost`, objective (11) in general
form) against the optimum.

Rules: ``consolidating`` (what such a fleet learns by when it names no rule: each type
consolidates on the recent targets that needed it, :attr:`Fleet.learns_per_type`),
``probe`` (the default before, and still for a fleet with stands or a type of several
speeds; a target that needs a type makes no probe) and ``paper`` (eq. (10) alone); from a
*cold* start (random positions) and a *warm* one (at the optimum). The named baseline, in
the same run on the same targets, is the batch answer: per type, the p-median of the
targets seen so far that needed that type. Beside it, ``per_type``: one consolidating
fleet of identical vehicles per type, each fed the targets that needed its type (the
decomposition, built apart; ``same_as_per_type`` counts the records where one fleet
learned exactly as it did: all of them with one type a target; with ``thirds`` one fleet
makes one consolidation a target, the separate ones may make two). Medians over seeds;
the worst network counts; the goals are those of the learning issue.

``--demand`` takes any of ``simulate``'s demand specs instead of the three hotspots
(``uniform``, ``hotspots:8``, ...). ``--rest`` adds one cold curve (the first network,
size and seed) through the REST API of a live ``routing-svc serve``: the fleet created
without a rule, each target posted with what it needs through ``targets:batch``; the
record's in-process curve beside it.

Run: ``python bench/heterogeneous.py`` (seven networks, 8 and 20 vehicles, seeds 0-2) or,
e.g., ``python bench/heterogeneous.py --nets drt --vehicles 8 --seeds 0 --mix thirds``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from bench_shared import NETWORKS, finished, network_name, refuse_unknown
from learning import DEFAULT_DEMAND, Instance, instance, refuse_degenerate, rest_run, wire

from routing_svc.demand import DemandDistribution
from routing_svc.optimum import solve_demand
from routing_svc.optimum.heterogeneous import (
    RequirementClass,
    heterogeneous_cost,
    solve_heterogeneous,
)
from routing_svc.sa import Fleet, Objective, Vehicle, learning_config
from routing_svc.sim.command import parse_seeds
from routing_svc.types import FloatArray, NetPosition

TYPES = ("A", "B")
MIXES = {
    "one-of-two": (RequirementClass(("A",), 0.5), RequirementClass(("B",), 0.5)),
    "thirds": (
        RequirementClass(("A",), 1 / 3),
        RequirementClass(("B",), 1 / 3),
        RequirementClass(("A", "B"), 1 / 3),
    ),
    "mostly-any": (
        RequirementClass((), 0.6),
        RequirementClass(("A",), 0.2),
        RequirementClass(("B",), 0.2),
    ),
}
"""Requirement mixes: each target needs one A or one B; or a third of them an A and a B;
or most (60 %) any one vehicle, the rest one A or one B."""
RULES = ("probe", "paper", "consolidating")
PER_TYPE = "per_type"
SCENARIOS = ("cold", "warm")
CHECKPOINTS = (300, 1000, 3000, 10000)
GOALS = {"cold_3000": 0.05, "warm_every": 0.05, "warm_from_3000": 0.015}

Job = tuple[str, int, int, int, str, str, bool]


def optimum_of(
    inst: Instance, types: list[str], speeds: FloatArray, mix: tuple[RequirementClass, ...]
) -> tuple[list[NetPosition], float]:
    """Each vehicle's position at the optimum of objective (11), and its value: with
    targets of one type each, the p-median of the demand per type (the decomposition,
    valued by the p-medians); else the best found by :func:`solve_heterogeneous` over
    the instance's candidate sites (valued by it)."""
    if all(len(c.requires) == 1 for c in mix):
        per_type = {t: solve_demand(inst.space, inst.demand, types.count(t)) for t in TYPES}
        value = sum(c.share * per_type[c.requires[0]].objective for c in mix)
        return [p for t in TYPES for p in per_type[t].positions], value
    weights = np.asarray(inst.demand.weights)
    found = solve_heterogeneous(inst.matrix, weights, types, speeds, mix, method="heuristic")
    return [inst.sites[i] for i in found.sites], found.objective


@dataclass(frozen=True)
class Setting:
    """One network, fleet size, seed and mix: the fleet's types, the optimum, the targets
    and what each needs."""

    inst: Instance
    mix: tuple[RequirementClass, ...]
    types: list[str]
    speeds: FloatArray
    at_optimum: list[NetPosition]
    optimum: float
    stream: list[NetPosition]
    needs: list[list[str]]

    def gap(self, positions: list[NetPosition]) -> float:
        """The exact objective (11) of ``positions`` against the optimum's, less 1."""
        value = heterogeneous_cost(
            self.inst.space, positions, self.types, self.speeds, self.inst.demand, self.mix
        )
        return float(value / self.optimum - 1.0)


def setting(
    net: str, n: int, seed: int, targets: int, mix_name: str, demand: str, anywhere: bool = False
) -> Setting:
    mix = MIXES[mix_name]
    inst = instance(net, n, seed, demand, shift=False, anywhere=anywhere)
    refuse_degenerate(inst, net, n)
    types = [TYPES[0]] * (n // 2) + [TYPES[1]] * (n - n // 2)
    speeds = np.ones(n)
    at_optimum, optimum = optimum_of(inst, types, speeds, mix)
    rng = np.random.default_rng([seed, 1])
    stream = inst.demand.sample(rng, targets)
    bounds = np.cumsum([c.share for c in mix])
    needs = [
        list(mix[min(int(np.searchsorted(bounds, u, side="right")), len(mix) - 1)].requires)
        for u in rng.random(targets)
    ]
    return Setting(inst, mix, types, speeds, at_optimum, optimum, stream, needs)


def job(args: Job) -> dict[str, Any]:
    net, n, seed, targets, mix_name, demand, anywhere = args
    t0 = time.perf_counter()
    case = setting(net, n, seed, targets, mix_name, demand, anywhere)
    inst, space, types, gap = case.inst, case.inst.space, case.types, case.gap
    at_optimum, optimum, stream, needs = case.at_optimum, case.optimum, case.stream, case.needs
    marks = [k for k in CHECKPOINTS if k <= targets]
    record: dict[str, Any] = {
        "network": network_name(net),
        "vehicles": n,
        "seed": seed,
        "optimum": optimum,
        "gap_at_optimum": gap(at_optimum),  # the evaluator against the optimum's value: 0
        "batch": {},
    }
    for k in marks:
        positions = []
        for t in TYPES:
            seen = [z for z, need in zip(stream[:k], needs[:k], strict=True) if t in need]
            sample = DemandDistribution.of_targets(f"seen {t}", seen)
            positions += solve_demand(space, sample, types.count(t), method="heuristic").positions
        record["batch"][str(k)] = gap(positions)
    for rule in RULES:
        record[rule] = {}
        for scenario in SCENARIOS:
            config = learning_config(
                rule,
                typical_cost=space.typical_cost(),
                n_vehicles=n,
                objective=Objective(1.0),
                seed=seed,
            )
            start = at_optimum if scenario == "warm" else inst.random_start
            vehicles = [(Vehicle(f"v{i:03d}", types[i]), p) for i, p in enumerate(start)]
            fleet = Fleet.create(space, vehicles, config)
            gaps = {}
            for k, (z, need) in enumerate(zip(stream, needs, strict=True), start=1):
                fleet.observe(z, need)
                if k in marks:
                    gaps[str(k)] = gap(list(fleet.state.positions))
            record[rule][scenario] = gaps
    record[PER_TYPE] = {}
    for scenario in SCENARIOS:
        start = at_optimum if scenario == "warm" else inst.random_start
        parts = {}
        for t in TYPES:
            mine = [i for i in range(n) if types[i] == t]
            config = learning_config(
                "consolidating",
                typical_cost=space.typical_cost(),
                n_vehicles=len(mine),
                objective=Objective(1.0),
                seed=seed,
            )
            parts[t] = Fleet.create(
                space, [(Vehicle(f"v{i:03d}", t), start[i]) for i in mine], config
            )
        gaps = {}
        for k, (z, need) in enumerate(zip(stream, needs, strict=True), start=1):
            for t in sorted(set(need)):
                parts[t].observe(z)
            if k in marks:
                gaps[str(k)] = gap([p for t in TYPES for p in parts[t].state.positions])
        record[PER_TYPE][scenario] = gaps
    record["seconds"] = time.perf_counter() - t0
    print(f"{record['network']} n={n} seed={seed}: {record['seconds']:.0f} s", file=sys.stderr)
    return record


def summarise(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians over seeds per network and size; per checkpoint, the worst of them."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in records:
        groups.setdefault(f"{r['network']}/{r['vehicles']}", []).append(r)
    table: dict[str, dict[str, Any]] = {}
    for key, rs in sorted(groups.items()):
        entry: dict[str, Any] = {
            "batch": {k: statistics.median(r["batch"][k] for r in rs) for k in rs[0]["batch"]}
        }
        for rule in (*RULES, PER_TYPE):
            entry[rule] = {
                s: {k: statistics.median(r[rule][s][k] for r in rs) for k in rs[0][rule][s]}
                for s in SCENARIOS
            }
        table[key] = entry
    labels = list(records[0]["batch"])
    worst: dict[str, Any] = {
        "batch": {k: max((e["batch"][k], key) for key, e in table.items()) for k in labels}
    }
    for rule in (*RULES, PER_TYPE):
        worst[rule] = {
            s: {k: max((e[rule][s][k], key) for key, e in table.items()) for k in labels}
            for s in SCENARIOS
        }
    goals = {}
    for rule in (*RULES, PER_TYPE):
        cold, warm = worst[rule]["cold"], worst[rule]["warm"]
        late = [k for k in labels if int(k) >= 3000]
        goals[rule] = {
            "cold_3000": [*cold["3000"], cold["3000"][0] <= GOALS["cold_3000"]]
            if "3000" in cold
            else None,
            "warm_every": [*max(warm.values()), max(warm.values())[0] <= GOALS["warm_every"]],
            "warm_from_3000": [
                *max(warm[k] for k in late),
                max(warm[k] for k in late)[0] <= GOALS["warm_from_3000"],
            ]
            if late
            else None,
        }
    return {"median_over_seeds": table, "worst_network": worst, "goals": goals}


def rest_curve(
    net: str, n: int, seed: int, targets: int, mix_name: str, demand: str, anywhere: bool = False
) -> dict[str, Any]:
    """The cold curve of the default rule through a live ``routing-svc serve``: a fleet of
    the two types created without a rule, the targets posted with what they need."""
    case = setting(net, n, seed, targets, mix_name, demand, anywhere)
    network = case.inst.space.network
    vehicles = [
        {"id": f"v{i:03d}", "type": case.types[i], "position": wire(network, p)}
        for i, p in enumerate(case.inst.random_start)
    ]
    fleet = {"id": "bench", "network": network_name(net), "vehicles": vehicles}
    bodies = [
        {"position": wire(network, z), "requires": need}
        for z, need in zip(case.stream, case.needs, strict=True)
    ]
    run = rest_run(net, network, fleet, bodies, CHECKPOINTS, case.gap)
    return {"network": network_name(net), "vehicles": n, "seed": seed, **run}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--nets", default=",".join(NETWORKS))
    p.add_argument("--vehicles", type=parse_seeds, default="8,20")
    p.add_argument("--seeds", type=parse_seeds, default="0,1,2")
    p.add_argument("--targets", type=int, default=max(CHECKPOINTS))
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--mix", choices=sorted(MIXES), default="one-of-two")
    p.add_argument(
        "--demand",
        default=DEFAULT_DEMAND,
        help="where targets are, as simulate's --demand (default hotspots:3)",
    )
    p.add_argument(
        "--anywhere",
        action="store_true",
        help=(
            "targets anywhere along the road, as bench/learning.py --anywhere, with its "
            "optimum over the starts of the pieces; priced on the fine model (five atoms "
            "a piece, the midpoint rule), as objective (11) needs its atoms"
        ),
    )
    p.add_argument("--rest", action="store_true", help="add one cold curve through the REST API")
    args = p.parse_args()
    refuse_unknown(p, args.nets.split(","), [args.demand])
    if args.targets < min(CHECKPOINTS) or args.jobs < 1:
        p.error(f"--targets must be at least {min(CHECKPOINTS)} and --jobs at least 1")
    if any(n < 2 for n in args.vehicles):
        p.error("--vehicles: at least 2 (one of each type)")
    started = time.perf_counter()
    jobs: list[Job] = [
        (net, n, seed, args.targets, args.mix, args.demand, args.anywhere)
        for net in args.nets.split(",")
        for n in args.vehicles
        for seed in args.seeds
    ]
    with ProcessPoolExecutor(args.jobs) as pool:
        records = list(pool.map(job, jobs))
    report = {
        "benchmark": "heterogeneous",
        "types": list(TYPES),
        "mix": [{"requires": list(c.requires), "share": c.share} for c in MIXES[args.mix]],
        "demand": args.demand,
        "anywhere": args.anywhere,
        "baseline": "batch: per type, the p-median of the targets seen so far that needed it",
        "gap": "exact expected cost of objective (11) / optimum - 1",
        **summarise(records),
        "same_as_per_type": sum(r["consolidating"] == r[PER_TYPE] for r in records),
    }
    report = finished(report, records, started)
    if args.rest:
        net, n, seed = args.nets.split(",")[0], args.vehicles[0], args.seeds[0]
        curve = rest_curve(net, n, seed, args.targets, args.mix, args.demand, args.anywhere)
        first = next(
            r
            for r in records
            if r["network"] == network_name(net) and r["vehicles"] == n and r["seed"] == seed
        )
        report["rest"] = {**curve, "in_process": first["consolidating"]["cold"]}
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
