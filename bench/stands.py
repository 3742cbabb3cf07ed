"""What restricting a fleet to stands costs, and how close learning between stands gets.

On Bad Hersfeld with its SUMO ``parkingArea`` stands
(``../shared/nets/badhersfeld.parking.add.xml``, those the network can use), for
each demand (``hotspots:3`` drawn from the seed, and the buildings of the town),
seed and fleet size:

- ``ratio``: the optimum over stands (:func:`routing_svc.optimum.stands.solve_stands`,
  exact over every stand unless ``stand_proven_optimal`` is false) over the free
  optimum (:func:`routing_svc.optimum.solve_demand`, the best-known p-median over
  its candidate sites), each the exact expected cost of the demand; what parking
  only at stands costs;
- ``gaps``: a ``consolidating`` fleet restricted to the stands, started at random
  stands, learns from targets drawn from the demand; after each checkpoint the
  exact expected cost from its vehicles' stands (:meth:`routing_svc.sa.Fleet.stands`)
  as a gap to the optimum over stands (negative where the fleet found stands better
  than an unproven optimum).

Prints JSON. Run: ``python bench/stands.py`` (or ``--sizes 8 --seeds 0 --targets 3000``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from bench_shared import SHARED

from routing_svc.demand import DemandDistribution
from routing_svc.demand.spec import network_demand, parse_demand_spec
from routing_svc.network import RoadSpace, load_network
from routing_svc.network.stands import read_stands_file
from routing_svc.optimum import expected_cost, solve_demand
from routing_svc.optimum.stands import solve_stands
from routing_svc.sa import Fleet, Objective, Vehicle, learning_config
from routing_svc.sa.stands import StandSet
from routing_svc.types import NetPosition

DEMANDS = ("hotspots:3", f"buildings:{SHARED / 'badhersfeld.buildings.csv'}")
CHECKPOINTS = (3000, 10000)
STAND_TIME_LIMIT = 300.0
"""Seconds of the exact method over the stands (the MILP of every stand, proof sought)."""


def one_case(
    space: RoadSpace,
    stands: StandSet[NetPosition],
    demand: DemandDistribution[NetPosition],
    n: int,
    seed: int,
    targets: int,
) -> dict[str, Any]:
    """The two optima, and a stand fleet's gaps at the checkpoints."""
    t0 = time.perf_counter()
    free = solve_demand(space, demand, n)
    over_stands = solve_stands(space, demand, n, stands, time_limit=STAND_TIME_LIMIT)
    solve_seconds = time.perf_counter() - t0
    config = replace(
        learning_config(
            "consolidating",
            typical_cost=space.typical_cost(),
            n_vehicles=n,
            objective=Objective(1.0),
            seed=seed,
        ),
        stands=stands,
    )
    rng = np.random.default_rng([seed, 3])
    start = rng.choice(len(stands.positions), size=n, replace=False)
    vehicles = [(Vehicle(f"v{i:03d}"), stands.positions[int(s)]) for i, s in enumerate(start)]
    fleet = Fleet.create(space, vehicles, config)
    stream = demand.sample(np.random.default_rng([seed, 1]), targets)
    gaps: dict[str, float] = {}
    t0 = time.perf_counter()
    for k, z in enumerate(stream, start=1):
        fleet.observe(z)
        if k in CHECKPOINTS:
            at = list(fleet.stands().values())
            value = expected_cost(space, at, np.ones(n), demand)
            gaps[str(k)] = (value - over_stands.objective) / over_stands.objective
    return {
        "free_optimum": free.objective,
        "stand_optimum": over_stands.objective,
        "ratio": over_stands.objective / free.objective,
        "free_method": free.solution.method,
        "stand_method": over_stands.solution.method,
        "stand_proven_optimal": over_stands.solution.proven_optimal,
        "stand_lower_bound": over_stands.solution.lower_bound,
        "gaps": gaps,
        "solve_seconds": solve_seconds,
        "learning_seconds": time.perf_counter() - t0,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default=str(SHARED / "badhersfeld.net.xml.gz"))
    parser.add_argument("--stands", default=str(SHARED / "badhersfeld.parking.add.xml"))
    parser.add_argument("--sizes", default="8,20")
    parser.add_argument("--seeds", default="0,1")
    parser.add_argument("--targets", type=int, default=max(CHECKPOINTS))
    parser.add_argument(
        "--demands", default="hotspots,buildings", help="of hotspots, buildings (comma-separated)"
    )
    args = parser.parse_args()
    network = load_network(Path(args.net))
    space = RoadSpace(network)
    reading = read_stands_file(Path(args.stands), network)
    stands = StandSet.merged(
        [(p, s.capacity) for p, s in zip(reading.positions(network), reading.usable, strict=True)]
    )
    sizes = [int(v) for v in args.sizes.split(",")]
    seeds = [int(v) for v in args.seeds.split(",")]
    cases: list[dict[str, Any]] = []
    chosen = args.demands.split(",")
    for spec in (d for d in DEMANDS if d.split(":")[0] in chosen):
        for seed in seeds:
            demand = network_demand(
                network, parse_demand_spec(spec), rng=np.random.default_rng([seed, 0])
            )
            for n in sizes:
                case = one_case(space, stands, demand, n, seed, args.targets)
                case |= {"demand": spec.split(":")[0], "seed": seed, "vehicles": n}
                cases.append(case)
                print(json.dumps(case), file=sys.stderr)
    summary = {
        f"{d}/{n}": {
            "ratio_median": statistics.median(c["ratio"] for c in group),
            **{
                f"gap_{k}_median": statistics.median(c["gaps"][k] for c in group)
                for k in group[0]["gaps"]
            },
        }
        for d in ("hotspots", "buildings")
        for n in sizes
        if (group := [c for c in cases if c["demand"] == d and c["vehicles"] == n])
    }
    print(
        json.dumps(
            {
                "net": args.net,
                "stands": {
                    "usable": len(reading.usable),
                    "dropped": len(reading.dropped),
                    "distinct": len(stands.positions),
                },
                "summary": summary,
                "cases": cases,
            },
            indent=2,
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
