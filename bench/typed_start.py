"""A fleet of several types created from a history that names each call's types.

Calls of two types come from two demands drawn apart (each ``--demand``, its own
seed): a share ``0.6`` needs one vehicle of type ``A``, ``0.4`` one of type ``B``.
A history of ``--calls`` such calls is written to CSV and a fleet ``A:5,B:3`` is
created from it by ``routing-svc history create-fleet`` in process, the user's path:

- ``own_calls``: the history with its ``types`` column; each type starts at the
  p-median of the calls that needed it (``start.optimum.requires``);
- ``all_calls`` (the baseline, the same run): the same calls without the column;
  each type starts at the p-median of all of them, as a sample without
  requirements starts.

Gap: objective (11) of the start on the two demands (targets that each need one
type: the shares times each type's exact expected cost) relative to the optimum,
each type's best-known p-median of its own demand.

Run: ``python bench/typed_start.py`` (seven networks, samples of 300 and 1,000
calls, seeds 0-4) or, e.g., ``python bench/typed_start.py --nets drt --seeds 0``.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from bench_shared import (
    NETWORKS,
    finished,
    medians_over_seeds,
    network_file,
    network_name,
    refuse_unknown,
    worst_and_mean_by_size,
)
from learning import DEFAULT_DEMAND

from routing_svc.demand.spec import network_demand, parse_demand_spec
from routing_svc.network import RoadSpace, load_network
from routing_svc.optimum import expected_cost, solve_demand
from routing_svc.sim.command import parse_seeds
from routing_svc.types import NetPosition

MIX = {"A": 5, "B": 3}
"""Vehicles per type."""

SHARES = {"A": 0.6, "B": 0.4}
"""The share of the calls that needs each type."""

RULES = ("own_calls", "all_calls")


def create_from_history(
    rows: list[list[Any]], net: str, *, typed: bool, tmp: Path
) -> list[dict[str, Any]]:
    """The vehicles of a fleet ``MIX`` created from ``rows`` by ``history create-fleet``."""
    label = "own" if typed else "all"
    path = tmp / f"{label}.csv"
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["time", "edge", "offset", *(["types"] if typed else [])])
        writer.writerows(row if typed else row[:3] for row in rows)
    mix = ",".join(f"{kind}:{count}" for kind, count in MIX.items())
    command = [
        sys.executable, "-m", "routing_svc.cli", "history", "create-fleet", str(path),
        "--fleet", "f", "--net", f"net={net}", "--vehicles", mix,
        "--db", str(tmp / f"{label}.db"), "--quiet",
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(done.stderr)
    vehicles: list[dict[str, Any]] = json.loads(done.stdout)["vehicles"]
    return vehicles


def job(net: str, demand: str, calls: int, seed: int) -> dict[str, Any]:
    path = network_file(net)
    network = load_network(path)
    space = RoadSpace(network, cost="length")
    recipe = parse_demand_spec(demand)
    demands = {
        kind: network_demand(network, recipe, rng=np.random.default_rng([seed, 7, i]))
        for i, kind in enumerate(MIX)
    }
    optimum = sum(
        SHARES[kind] * solve_demand(space, demands[kind], MIX[kind]).objective for kind in MIX
    )
    rng = np.random.default_rng([seed, 9])
    kinds = rng.choice(list(MIX), size=calls, p=[SHARES[k] for k in MIX]).tolist()
    rows: list[list[Any]] = []
    for t, kind in enumerate(kinds):
        z = demands[kind].sample(rng, 1)[0]
        rows.append([t, network.edge_ids[z.edge], z.offset, kind])
    type_of = [kind for kind, count in MIX.items() for _ in range(count)]
    gaps = {}
    with tempfile.TemporaryDirectory() as tmp:
        for rule in RULES:
            vehicles = create_from_history(rows, path, typed=rule == "own_calls", tmp=Path(tmp))
            total = 0.0
            for kind in MIX:
                at = [
                    NetPosition(network.edge_index[v["edge"]], float(v["offset"]))
                    for v in vehicles
                    if type_of[int(v["id"][1:])] == kind
                ]
                total += SHARES[kind] * expected_cost(space, at, np.ones(len(at)), demands[kind])
            gaps[rule] = total / optimum - 1.0
    return {
        "network": network_name(net),
        "demand": demand,
        "calls": calls,
        "seed": seed,
        "gaps": gaps,
    }


def summarise(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians over seeds per case; per sample size, the worst network and the mean."""
    medians = medians_over_seeds(
        records, lambda r: f"{r['network']}/{r['demand']}/{r['calls']}", RULES
    )
    by_size: dict[str, Any] = worst_and_mean_by_size(medians, (r["calls"] for r in records), RULES)
    for summary in by_size.values():
        own, every = (summary[rule]["mean_of_medians"] for rule in RULES)
        summary["ratio_own_over_all"] = own / every if every else None
    return {"median_over_seeds": medians, "by_calls": by_size}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--nets", default=",".join(NETWORKS))
    p.add_argument("--demand", default=DEFAULT_DEMAND)
    p.add_argument("--calls", type=parse_seeds, default="300,1000")
    p.add_argument("--seeds", type=parse_seeds, default="0,1,2,3,4")
    args = p.parse_args()
    refuse_unknown(p, args.nets.split(","), [args.demand])
    if min(args.calls) < sum(MIX.values()):
        p.error(f"--calls: a history needs at least {sum(MIX.values())} calls")
    started = time.perf_counter()
    records = [
        job(net, args.demand, calls, seed)
        for net in args.nets.split(",")
        for calls in args.calls
        for seed in args.seeds
    ]
    report = {
        "benchmark": "typed_start",
        "fleet": MIX,
        "shares": SHARES,
        "baseline": "all_calls (each type at the p-median of every call, the same run)",
        "gap": "objective (11) on the two demands, relative to the per-type optima",
        **summarise(records),
    }
    print(json.dumps(finished(report, records, started), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
