"""``routing-svc simulate``: an offline SA run (no SUMO needed) with the gap to the optimum.

Targets are drawn from a named demand distribution (uniform over edge length,
a hotspot mixture, or weights from a file) on a road network or on the plane;
the fleet learns by the paper's rule, and the exact expected cost of its
configuration (no sampling) is reported over time against the exact (or
best-known) p-median of the same distribution.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.errors import InvalidInput
from routing_svc.json_text import json_text
from routing_svc.optimum import expected_cost, gap, solve_demand
from routing_svc.sa import (
    DEFAULT_RULE,
    Annealing,
    Fleet,
    Objective,
    Rule,
    Vehicle,
    learning_config,
    prior_counts,
)


@dataclass(frozen=True)
class Scenario:
    """A space, its demand, the candidate sites of the optimum and the start positions.

    ``sites`` is ``None`` on a road network: the optimum's candidate sites are then
    :func:`routing_svc.optimum.solve_demand`'s (demand atoms and edge ends).
    """

    space: Any
    demand: DemandDistribution[Any]
    sites: list[Any] | None
    starts: list[Any]
    describe: Any


def network_scenario(
    net: str, *, demand: str, vehicles: int, cost: str, rng: np.random.Generator
) -> Scenario:
    """A road-network scenario (``net`` is a known name or a path)."""
    from routing_svc.demand.spec import network_demand, parse_demand_spec
    from routing_svc.network import RoadSpace, load_network
    from routing_svc.network.catalogue import resolve_network
    from routing_svc.types import NetPosition

    network = load_network(resolve_network(net))
    space = RoadSpace(network, cost=cost)  # type: ignore[arg-type]
    dist = network_demand(network, parse_demand_spec(demand), rng=rng)
    edges = rng.choice(network.n_edges, size=vehicles, replace=vehicles > network.n_edges)
    starts = [NetPosition(int(e), 0.0) for e in edges]

    def describe(p: NetPosition) -> dict[str, Any]:
        x, y = space.xy(p)
        return {"edge": network.edge_ids[p.edge], "offset": p.offset, "x": x, "y": y}

    return Scenario(space, dist, None, starts, describe)


def plane_scenario(*, demand: str, vehicles: int, rng: np.random.Generator) -> Scenario:
    """The unit-free plane ``[0, 10]^2`` of the paper."""
    from routing_svc.demand import gaussian_mixture, uniform_rectangle
    from routing_svc.demand.spec import Hotspots, Uniform, parse_demand_spec
    from routing_svc.sa import EuclideanPlane
    from routing_svc.types import PlanePosition

    bounds = (0.0, 0.0, 10.0, 10.0)
    form = parse_demand_spec(demand).form
    if isinstance(form, Uniform):
        dist = uniform_rectangle(bounds, cells=30)
    elif isinstance(form, Hotspots):
        centres = [tuple(c) for c in rng.uniform(1.5, 8.5, size=(form.count, 2))]
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
    start: str = "first",
    checkpoints: int = 20,
    progress: bool = True,
    probe: float | None = None,
    step_scale: float | None = None,
    rule: Rule = DEFAULT_RULE,
) -> dict[str, Any]:
    """Run the SA on ``targets`` draws and report the exact objective over time.

    ``start`` chooses the first configuration: ``random`` (the scenario's
    random positions), ``first`` (the first distinct targets of the stream, as
    MacQueen's online k-means starts) or ``prior:N`` (the p-median of the
    first ``N`` targets, the paper's "deterministic first configuration that
    the SA then refines"). Targets used to start count toward ``targets``,
    and toward each vehicle's step counter (the prior targets it serves), so
    that the SA goes on with the steps of a fleet that has seen them.
    ``rule`` is the learning rule (:func:`routing_svc.sa.learning_config`);
    ``probe`` the window of the ``probe`` rule's backward finite difference as a
    fraction of the cell radius ``R``; ``step_scale`` is ``a / R`` of the step
    schedule (default: the rule's).
    """
    from tqdm import tqdm

    rng = np.random.default_rng([seed, 1])
    space = scenario.space
    n = len(scenario.starts)
    stream = scenario.demand.sample(rng, targets)
    starts, used = starting_positions(scenario, stream, start=start, power=objective.power)
    config = learning_config(
        rule,
        typical_cost=space.typical_cost(),
        n_vehicles=n,
        objective=objective,
        seed=seed,
        annealing=annealing,
        probe=probe,
        step_scale=step_scale,
        prior_counts=prior_counts(space, starts, [1.0] * n, stream[:used])
        if start.startswith("prior")
        else (),
    )
    fleet = Fleet.create(space, [(Vehicle(f"v{i:03d}"), p) for i, p in enumerate(starts)], config)
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
    optimum = solve_demand(space, scenario.demand, n, sites=scenario.sites, power=objective.power)
    optimum_seconds = time.perf_counter() - started
    marks = sorted({round(x) for x in np.linspace(used, targets, checkpoints + 1)})
    curve = [{"targets": used, "expected_cost": value()}]
    consolidations = {"made": 0, "accepted": 0}
    sa_seconds = 0.0
    first_target_seconds = None
    done = used
    with tqdm(total=targets, disable=not progress, file=sys.stderr, unit="target") as bar:
        for mark in marks[1:]:
            batch = stream[done:mark]
            if first_target_seconds is None and batch:
                # The first target may compile the search and the update (numba, once per
                # machine): timed on its own so that the per-target figure is the SA's.
                t0 = time.perf_counter()
                fleet.observe(batch[0])
                first_target_seconds = time.perf_counter() - t0
                batch = batch[1:]
            t0 = time.perf_counter()
            for z in batch:
                made = fleet.observe(z).consolidation
                if made is not None:
                    consolidations["made"] += 1
                    consolidations["accepted"] += made.accepted
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
        "start": start,
        "rule": config.rule.value,
        "consolidations": consolidations,
        "probe": config.probe,
        "step": config.schedule.to_dict(),
        "demand": {"name": scenario.demand.name, "atoms": len(scenario.demand.positions)},
        "curve": curve,
        "final_expected_cost": final,
        "optimum": {
            "objective": optimum.objective,
            "method": optimum.solution.method,
            "proven_optimal": optimum.solution.proven_optimal,
            "sites": len(optimum.sites),
            "seconds": optimum_seconds,
        },
        "gap": gap(final, optimum.objective),
        "sa_microseconds_per_target": 1e6 * sa_seconds / max(targets - used - 1, 1),
        "sa_first_target_seconds": first_target_seconds,
        "positions": [scenario.describe(p) for p in fleet.state.positions],
    }


def starting_positions(
    scenario: Scenario, stream: list[Any], *, start: str, power: float
) -> tuple[list[Any], int]:
    """The fleet's first configuration and how many targets of the stream it used."""
    n = len(scenario.starts)
    if start == "random":
        return list(scenario.starts), 0
    if start == "first":
        chosen: list[Any] = []
        for used, z in enumerate(stream, start=1):
            if z not in chosen:
                chosen.append(z)
            if len(chosen) == n:
                return chosen, used
        raise InvalidInput(f"the stream has fewer than {n} distinct targets")
    kind, _, count = start.partition(":")
    if kind == "prior" and count.isdigit() and int(count) >= n:
        sample = stream[: min(int(count), len(stream))]
        prior = DemandDistribution.of_targets(f"prior:{len(sample)}", sample)
        if len(prior) < n:
            raise InvalidInput(f"the prior sample has fewer than {n} distinct targets")
        sites = list(prior.positions)
        # on a road network the service's candidates (the sample and edge ends, as a
        # fleet created at the optimum of a sample gets); on the plane the sample itself
        offered = None if scenario.sites is None else sites
        best = solve_demand(scenario.space, prior, n, sites=offered, power=power)
        return best.positions, len(sample)
    raise InvalidInput(f"--start must be random, first or prior:N with N >= {n}, got {start!r}")


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "simulate",
        help="offline SA run on a network or the plane; JSON with the gap to the optimum",
    )
    p.add_argument("--net", default="drt", help="network name or path (default: drt)")
    p.add_argument("--plane", action="store_true", help="use the Euclidean plane [0,10]^2")
    p.add_argument("--vehicles", type=int, default=10, help="fleet size (default: 10)")
    p.add_argument(
        "--targets",
        type=int,
        default=20000,
        help="targets in the stream, those used to start included (default: 20000)",
    )
    p.add_argument(
        "--demand",
        default="hotspots:3",
        help="uniform | hotspots[:K] | weights:FILE | buildings:FILE (the plane: uniform or "
        "hotspots[:K]); see routing_svc.demand.spec",
    )
    p.add_argument(
        "--cost",
        choices=["length", "time"],
        default="length",
        help="shortest-path cost: metres or free-flow travel time (default: length)",
    )
    p.add_argument("--objective", default="routing", help="routing | coverage | power q >= 1")
    p.add_argument(
        "--annealing",
        type=float,
        default=None,
        metavar="SCALE",
        help="annealing noise scale as a fraction of the typical trip cost",
    )
    p.add_argument(
        "--seed", type=int, default=0, help="seed of the demand, the stream and the noise"
    )
    p.add_argument(
        "--start",
        default="prior:3000",
        help="first (the first distinct targets) | random | prior:N "
        "(p-median of the first N targets; default prior:3000)",
    )
    p.add_argument(
        "--rule",
        choices=[r.value for r in Rule],
        default=DEFAULT_RULE.value,
        help="learning rule: consolidating (default: held steps and consolidations), "
        "probe (the paper's step and the backward probe) or paper (eq. (10) alone)",
    )
    p.add_argument(
        "--probe",
        type=float,
        default=None,
        metavar="FRACTION",
        help="the probe rule's window of the backward finite difference, as a fraction "
        "of the cell radius R (default 0.05)",
    )
    p.add_argument(
        "--step-scale",
        type=float,
        default=None,
        help="first step a = step_scale * R of the default schedule "
        "(default 0.01 for consolidating, 0.5 otherwise)",
    )
    p.add_argument(
        "--checkpoints",
        type=int,
        default=20,
        help="points of the objective curve, each an exact expected cost (default: 20)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.vehicles < 1 or args.targets < 0 or args.checkpoints < 1:
        raise InvalidInput("--vehicles and --checkpoints must be >= 1, --targets >= 0")
    if args.probe is not None and not (math.isfinite(args.probe) and args.probe >= 0.0):
        raise InvalidInput("--probe must be a fraction >= 0 (0: the paper's rule alone)")
    if args.step_scale is not None and not (
        math.isfinite(args.step_scale) and args.step_scale > 0.0
    ):
        raise InvalidInput("--step-scale must be a number > 0")
    rule = Rule(args.rule)
    if args.probe is not None and rule is not Rule.PROBE:
        raise InvalidInput("--probe goes with --rule probe")
    if args.plane and rule is Rule.PROBE:
        raise InvalidInput("the probe rule needs a road network, not --plane")
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
        start=args.start,
        checkpoints=args.checkpoints,
        progress=not args.quiet,
        probe=args.probe,
        step_scale=args.step_scale,
        rule=rule,
    )
    print(json_text(report, indent=2))
    return 0
