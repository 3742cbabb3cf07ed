"""``routing-svc simulate``: an offline SA run (no SUMO needed) with the gap to the optimum.

Targets are drawn from a named demand distribution (uniform over edge length,
a hotspot mixture, or weights from a file) on a road network or on the plane;
the fleet learns by the paper's rule, and the exact expected cost of its
configuration (no sampling) is reported over time against the exact (or
best-known) p-median of the same distribution.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.errors import InvalidInput
from routing_svc.optimum import expected_cost, solve_pmedian
from routing_svc.sa import Annealing, Fleet, FleetConfig, Objective, Vehicle, default_schedule


@dataclass(frozen=True)
class Scenario:
    """A space, its demand, the candidate sites of the optimum and the start positions."""

    space: Any
    demand: DemandDistribution[Any]
    sites: list[Any]
    starts: list[Any]
    describe: Any


def network_scenario(
    net: str, *, demand: str, vehicles: int, cost: str, rng: np.random.Generator
) -> Scenario:
    """A road-network scenario (``net`` is a known name or a path)."""
    from routing_svc.demand import network as network_demand
    from routing_svc.nets import resolve_network
    from routing_svc.network import RoadSpace, load_network
    from routing_svc.optimum import candidate_sites
    from routing_svc.types import NetPosition

    network = load_network(resolve_network(net))
    space = RoadSpace(network, cost=cost)  # type: ignore[arg-type]
    kind, _, arg = demand.partition(":")
    if kind == "uniform":
        dist = network_demand.uniform_by_length(network)
    elif kind == "hotspots":
        count = int(arg) if arg else 3
        dist = network_demand.hotspot_mixture(network, centres=count, rng=rng)
    elif Path(demand).is_file():
        dist = network_demand.from_weights_file(network, Path(demand))
    else:
        raise InvalidInput(
            f"--demand must be 'uniform', 'hotspots[:K]' or a weights file, got {demand!r}"
        )
    edges = rng.choice(network.n_edges, size=vehicles, replace=vehicles > network.n_edges)
    starts = [NetPosition(int(e), 0.0) for e in edges]
    sites = candidate_sites(network, dist, max_sites=1500)

    def describe(p: NetPosition) -> dict[str, Any]:
        x, y = space.xy(p)
        return {"edge": network.edge_ids[p.edge], "offset": p.offset, "x": x, "y": y}

    return Scenario(space, dist, list(sites), starts, describe)


def plane_scenario(*, demand: str, vehicles: int, rng: np.random.Generator) -> Scenario:
    """The unit-free plane ``[0, 10]^2`` of the paper."""
    from routing_svc.demand import gaussian_mixture, uniform_rectangle
    from routing_svc.sa import EuclideanPlane
    from routing_svc.types import PlanePosition

    bounds = (0.0, 0.0, 10.0, 10.0)
    kind, _, arg = demand.partition(":")
    if kind == "uniform":
        dist = uniform_rectangle(bounds, cells=30)
    elif kind == "hotspots":
        count = int(arg) if arg else 3
        centres = [tuple(c) for c in rng.uniform(1.5, 8.5, size=(count, 2))]
        dist = gaussian_mixture(bounds, centres=centres, spread=1.0, cells=30)
    else:
        raise InvalidInput("on the plane --demand must be 'uniform' or 'hotspots[:K]'")
    space = EuclideanPlane(side=10.0)
    starts = [PlanePosition(float(x), float(y)) for x, y in rng.uniform(0, 10, size=(vehicles, 2))]
    return Scenario(space, dist, list(dist.positions), starts, space.encode)


def run_simulation(
    scenario: Scenario,
    *,
    targets: int,
    objective: Objective,
    annealing: Annealing | None,
    seed: int,
    checkpoints: int = 20,
    progress: bool = True,
) -> dict[str, Any]:
    """Run the SA on ``targets`` draws and report the exact objective over time."""
    from tqdm import tqdm

    rng = np.random.default_rng([seed, 1])
    space = scenario.space
    n = len(scenario.starts)
    config = FleetConfig(
        objective=objective,
        schedule=default_schedule(
            typical_cost=space.typical_cost(), n_vehicles=n, power=objective.power
        ),
        annealing=annealing,
        seed=seed,
    )
    fleet = Fleet.create(
        space, [(Vehicle(f"v{i:03d}"), p) for i, p in enumerate(scenario.starts)], config
    )
    speeds = np.ones(n)

    def value() -> float:
        return expected_cost(
            space,
            fleet.state.positions,
            speeds,
            scenario.demand,
            power=objective.power,
        )

    started = time.perf_counter()
    matrix = space.cost_matrix(scenario.sites, list(scenario.demand.positions)) ** objective.power
    optimum = solve_pmedian(matrix, np.asarray(scenario.demand.weights), n)
    optimum_seconds = time.perf_counter() - started
    marks = sorted({round(x) for x in np.linspace(0, targets, checkpoints + 1)})
    curve = [{"targets": 0, "expected_cost": value()}]
    stream = scenario.demand.sample(rng, targets)
    sa_seconds = 0.0
    done = 0
    with tqdm(total=targets, disable=not progress, file=sys.stderr, unit="target") as bar:
        for mark in marks[1:]:
            t0 = time.perf_counter()
            for z in stream[done:mark]:
                fleet.observe(z)
            sa_seconds += time.perf_counter() - t0
            bar.update(mark - done)
            done = mark
            curve.append({"targets": mark, "expected_cost": value()})
    final = curve[-1]["expected_cost"]
    return {
        "vehicles": n,
        "targets": targets,
        "objective": objective.name,
        "annealing": None if annealing is None else annealing.to_dict(),
        "seed": seed,
        "step": config.schedule.to_dict(),
        "demand": {"name": scenario.demand.name, "atoms": len(scenario.demand.positions)},
        "curve": curve,
        "final_expected_cost": final,
        "optimum": {
            "objective": optimum.objective,
            "method": optimum.method,
            "proven_optimal": optimum.proven_optimal,
            "sites": len(scenario.sites),
            "seconds": optimum_seconds,
        },
        "gap": (final - optimum.objective) / optimum.objective,
        "sa_microseconds_per_target": 1e6 * sa_seconds / max(targets, 1),
        "positions": [scenario.describe(p) for p in fleet.state.positions],
    }


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "simulate",
        help="offline SA run on a network or the plane; JSON with the gap to the optimum",
    )
    p.add_argument("--net", default="drt", help="network name or path (default: drt)")
    p.add_argument("--plane", action="store_true", help="use the Euclidean plane [0,10]^2")
    p.add_argument("--vehicles", type=int, default=10)
    p.add_argument("--targets", type=int, default=20000)
    p.add_argument("--demand", default="hotspots:3", help="uniform | hotspots[:K] | weights file")
    p.add_argument("--cost", choices=["length", "time"], default="length")
    p.add_argument("--objective", default="routing", help="routing | coverage | power q >= 1")
    p.add_argument(
        "--annealing",
        type=float,
        default=None,
        metavar="SCALE",
        help="annealing noise scale as a fraction of the typical trip cost",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--checkpoints", type=int, default=20)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.vehicles < 1 or args.targets < 0 or args.checkpoints < 1:
        raise InvalidInput("--vehicles and --checkpoints must be >= 1, --targets >= 0")
    rng = np.random.default_rng(args.seed)
    if args.plane:
        scenario = plane_scenario(demand=args.demand, vehicles=args.vehicles, rng=rng)
    else:
        scenario = network_scenario(
            args.net, demand=args.demand, vehicles=args.vehicles, cost=args.cost, rng=rng
        )
    annealing = None
    if args.annealing is not None:
        annealing = Annealing(args.annealing * scenario.space.typical_cost(), 1.0)
    report = run_simulation(
        scenario,
        targets=args.targets,
        objective=Objective.parse(args.objective),
        annealing=annealing,
        seed=args.seed,
        checkpoints=args.checkpoints,
        progress=not args.quiet,
    )
    print(json.dumps(report, indent=2))
    return 0
