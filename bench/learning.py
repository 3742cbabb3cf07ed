"""Learning curves of every rule on every network, against the optimum and the batch answer.

For each network, fleet size and seed: a demand (by default three hotspots drawn
from the seed; ``--demand`` takes any of ``simulate``'s specs) and its best
p-median (the *optimum*); then, for each rule, the
exact expected cost of the fleet after 300, 1,000, 3,000, 10,000 and 30,000
targets as a gap to the optimum, from three starts:

- ``cold``: random positions;
- ``warm``: at the optimum's sites, with fresh step counters (a fleet created at
  good positions);
- ``shift``: cold, and after 10,000 targets the hotspots move; gaps to the new
  demand's optimum 1,000 and 5,000 targets later.

In the same run the *anchor*, the p-median of every target seen so far (the
batch answer) over the candidate sites of those targets (themselves and the edge
ends), is evaluated at the same checkpoints, and each rule's compute per
target is measured against ``probe``, the rule whose compiled update served
every fleet before (the named baseline). Medians over seeds; the worst network
counts. The distance behind the batch answer is given two ways: the median gap
less the batch answer's median gap (``behind_anchor_from_1000``), and the median
over seeds of each seed's gap less the batch answer of its own targets
(``behind_anchor_paired_from_1000``). The same targets solved over the demand's
candidate sites, which no batch solve of the targets knows, give the
``demand_site_anchor`` and its two distances. ``fit_behind_anchor_paired_from_1000`` tells
the two causes of such a distance apart: how much more the rule's references cost than the
batch answer's on the very targets seen (paired; at most 0 where the rule fits them as well).
An instance without an optimum to compare with (more vehicles than the network has
candidate sites) or whose optimum costs under :data:`DEGENERATE_FRACTION` of one
vehicle's (more vehicles than the demand has places) is not measured: its record says
why, and the summary lists it under ``not_measured``. ``--rest`` adds one curve through
the REST API of a live ``routing-svc serve`` (``targets:batch``).

Run: ``python bench/learning.py`` (everything; long) or, e.g.,
``python bench/learning.py --nets drt,bologna --seeds 0,1 --targets 10000``; a network
of your own is ``--nets town=town.net.xml.gz``; ``--cost time`` prices every path in
free-flow travel time instead of metres; ``--anywhere`` draws targets anywhere along the
road, not at the demand's atoms only (:mod:`continuous`), each gap then integrated
exactly along the demand's pieces of road (:func:`continuous.priced_along`).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from bench_shared import NETWORKS, finished, network_file, network_name, refuse_unknown
from continuous import ContinuousDemand, piece_starts, priced_along
from continuous import continuous as along_the_road

from routing_svc.demand import DemandDistribution
from routing_svc.demand.spec import DemandRecipe, Hotspots, network_demand, parse_demand_spec
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork, RoadSpace, load_network
from routing_svc.network.costs import CostKind
from routing_svc.optimum import MAX_SITES, expected_cost, solve_demand, solve_pmedian
from routing_svc.optimum import gap as relative_gap
from routing_svc.sa import Fleet, Objective, Rule, Vehicle, learning_config
from routing_svc.types import FloatArray, NetPosition

DEFAULT_DEMAND = "hotspots:3"
CHECKPOINTS = (300, 1000, 3000, 10000, 30000)
SHIFT_AT = 10000
DEGENERATE_FRACTION = 0.005
"""An instance whose optimum costs less than this fraction of one vehicle's is not measured."""
AFTER_SHIFT = (1000, 5000)
GOALS: dict[str, Any] = {
    "cold": {"3000": 0.05, "30000": 0.02},
    "warm_every": 0.05,
    "warm_from_3000": 0.015,
    "shift_5000": 0.05,
    "anchor_points": 0.01,
    "compute_ratio": 2.0,
}


@dataclass(frozen=True)
class Instance:
    """A network, its demand (and the shifted one), their optima and a random start."""

    space: RoadSpace
    demand: DemandDistribution[NetPosition]
    shifted: DemandDistribution[NetPosition]
    optimum: tuple[float, list[NetPosition]]
    shifted_optimum: tuple[float, list[NetPosition]]
    matrix: FloatArray
    shifted_matrix: FloatArray
    sites: list[NetPosition]
    shifted_sites: list[NetPosition]
    random_start: list[NetPosition]


def optimum_of(
    space: RoadSpace, demand: DemandDistribution[NetPosition], n: int
) -> tuple[tuple[float, list[NetPosition]], FloatArray, list[NetPosition]]:
    best = solve_demand(space, demand, n)
    return (best.objective, best.positions), best.matrix, best.sites


def instance(
    net: str,
    n: int,
    seed: int,
    spec: str = DEFAULT_DEMAND,
    spread: float | None = None,
    cost: CostKind = "length",
    shift: bool = True,
    anywhere: bool = False,
) -> Instance:
    """The instance of ``net`` for ``n`` vehicles and ``seed``; ``shift=False`` leaves
    the shifted demand unsolved (it is then the demand itself); ``anywhere``: targets
    anywhere along the road (:func:`continuous.continuous`), priced exactly along its
    pieces (:func:`continuous.priced_along`)."""
    network = load_network(network_file(net))
    space = RoadSpace(network, cost=cost)
    recipe = parse_demand_spec(spec)
    if spread is not None and isinstance(recipe.form, Hotspots):
        xmin, ymin, xmax, ymax = network.bounds
        metres = spread * math.hypot(xmax - xmin, ymax - ymin)
        recipe = DemandRecipe(Hotspots(recipe.form.count, metres), recipe.profile)
    demand = network_demand(network, recipe, rng=np.random.default_rng([seed, 0]))
    optimum, matrix, sites = optimum_of(space, demand, n)
    if anywhere:
        demand, optimum, matrix, sites = anywhere_along(space, demand, n, optimum, sites)
    if shift and isinstance(recipe.form, Hotspots):  # the hotspots move: new centres
        shifted = network_demand(network, recipe, rng=np.random.default_rng([seed, 2]))
        shifted_optimum, shifted_matrix, shifted_sites = optimum_of(space, shifted, n)
        if anywhere:
            shifted, shifted_optimum, shifted_matrix, shifted_sites = anywhere_along(
                space, shifted, n, shifted_optimum, shifted_sites
            )
    else:  # a demand without centres to move (or not asked to) has no shift
        shifted, shifted_optimum, shifted_matrix, shifted_sites = demand, optimum, matrix, sites
    edges = np.random.default_rng([seed, 3]).choice(  # distinct edges while there are enough
        network.n_edges, size=n, replace=n > network.n_edges
    )
    start = [NetPosition(int(e), 0.0) for e in edges]
    return Instance(
        space,
        demand,
        shifted,
        optimum,
        shifted_optimum,
        matrix,
        shifted_matrix,
        sites,
        shifted_sites,
        start,
    )


def anywhere_along(
    space: RoadSpace,
    demand: DemandDistribution[NetPosition],
    n: int,
    optimum: tuple[float, list[NetPosition]],
    sites: list[NetPosition],
) -> tuple[
    DemandDistribution[NetPosition], tuple[float, list[NetPosition]], FloatArray, list[NetPosition]
]:
    """``demand`` drawn anywhere along the road, its optimum over the starts of the pieces
    of the candidate ``sites`` of ``demand`` (:func:`continuous.piece_starts`, priced
    exactly; or ``demand``'s own ``optimum``, priced by :func:`continuous.priced_along`,
    where that costs less), the starts' cost matrix to its fine model, and the starts."""
    fine = along_the_road(space.network, demand)
    starts = piece_starts(fine, sites)
    best = solve_demand(space, demand, n, sites=starts)
    found = (best.objective, best.positions)
    kept = priced_along(space, optimum[1], fine)
    matrix = np.asarray(space.cost_matrix(starts, list(fine.positions)), dtype=np.float64)
    return fine, (kept, optimum[1]) if kept < found[0] else found, matrix, starts


def gap(space: RoadSpace, positions: list[NetPosition], demand: Any, optimum: float) -> float:
    """The relative gap of ``positions`` to ``optimum`` on ``demand`` (targets anywhere
    along the road: priced exactly, :func:`continuous.priced_along`)."""
    if isinstance(demand, ContinuousDemand):
        value = priced_along(space, positions, demand)
    else:
        value = expected_cost(space, positions, np.ones(len(positions)), demand)
    relative = relative_gap(value, optimum)
    assert relative is not None  # a degenerate instance (an optimum of 0) is not measured
    return relative


def sample_cost(
    space: RoadSpace, positions: list[NetPosition], targets: list[NetPosition]
) -> float:
    """The mean cost of ``targets`` from their closest of ``positions``: objective (11) on the
    targets' empirical distribution, what a batch solve of them minimises."""
    seen = DemandDistribution.of_targets("seen", targets)
    return expected_cost(space, positions, np.ones(len(positions)), seen)


def run_rule(
    inst: Instance, rule: str, scenario: str, n: int, seed: int, targets: int
) -> dict[str, Any]:
    """One fleet of ``rule`` from ``scenario``'s start; its gaps at the checkpoints (and,
    from a cold start, its :func:`sample_cost` on the targets seen)."""
    space = inst.space
    config = learning_config(
        rule, typical_cost=space.typical_cost(), n_vehicles=n, objective=Objective(1.0), seed=seed
    )
    start = inst.optimum[1] if scenario == "warm" else inst.random_start
    fleet = Fleet.create(space, [(Vehicle(f"v{i:03d}"), p) for i, p in enumerate(start)], config)
    rng = np.random.default_rng([seed, 1])
    if scenario == "shift":
        stream = inst.demand.sample(rng, SHIFT_AT) + inst.shifted.sample(rng, max(AFTER_SHIFT))
        marks = {SHIFT_AT + k: f"+{k}" for k in AFTER_SHIFT}
    else:
        stream = inst.demand.sample(rng, targets)
        marks = {k: str(k) for k in CHECKPOINTS if k <= targets}
    gaps: dict[str, float] = {}
    fits: dict[str, float] = {}
    seconds = consolidating = 0.0
    made = accepted = 0
    _warm_up(inst, config, start, stream)
    fleet.observe(stream[0])
    for k, z in enumerate(stream[1:], start=2):
        t0 = time.perf_counter()
        outcome = fleet.observe(z)
        spent = time.perf_counter() - t0
        seconds += spent
        if outcome.consolidation is not None:
            consolidating += spent
            made += 1
            accepted += outcome.consolidation.accepted
        if k in marks:
            after = scenario == "shift"
            demand = inst.shifted if after else inst.demand
            optimum = inst.shifted_optimum[0] if after else inst.optimum[0]
            gaps[marks[k]] = gap(space, fleet.state.positions, demand, optimum)
            if scenario == "cold":
                fits[marks[k]] = sample_cost(space, fleet.state.positions, stream[:k])
    served = max(len(stream) - 1, 1)
    return {
        "gaps": gaps,
        **({"sample_costs": fits} if fits else {}),
        "microseconds_per_target": 1e6 * seconds / served,
        "step_microseconds_per_target": 1e6 * (seconds - consolidating) / max(served - made, 1),
        "consolidations": made,
        "accepted": accepted,
        "consolidation_seconds": consolidating,
    }


WARM_UP_TARGETS = 600
"""Targets a throwaway fleet serves before the timing, per rule and process."""

_warmed: set[str] = set()


def _warm_up(inst: Instance, config: Any, start: list[NetPosition], stream: list[Any]) -> None:
    """Compile or load every kernel the rule runs (search, held moves, a consolidation)
    once per process, outside the timing: a copy of the fleet on a space of its own (the
    timed fleet's space keeps no distance rows of it)."""
    if config.rule.value in _warmed:
        return
    _warmed.add(config.rule.value)
    space = RoadSpace(inst.space.network, cost=inst.space.cost_kind)
    vehicles = [(Vehicle(f"w{i:03d}"), p) for i, p in enumerate(start)]
    throwaway = Fleet.create(space, vehicles, config)
    for z in stream[:WARM_UP_TARGETS]:
        throwaway.observe(z)


def anchor_gaps(inst: Instance, n: int, seed: int, targets: int) -> dict[str, Any]:
    """The batch answer (p-median of all targets so far) at the checkpoints of each stream.

    ``cold`` and ``shift``: over the candidate sites of the targets themselves (the
    targets seen and the ends of the edges, :func:`targets_batch_answer`), all that a
    batch solve of them knows; ``demand_sites``: the same targets over the demand's candidate
    sites (its atoms and the edge ends, or the starts of their pieces), which a batch
    solve of the targets does not know; ``sample_costs``: the ``cold`` batch answer's
    :func:`sample_cost` on the targets it was solved from.
    """
    rng = np.random.default_rng([seed, 1])
    out: dict[str, Any] = {
        "cold": {},
        "shift": {},
        "demand_sites": {"cold": {}, "shift": {}},
        "sample_costs": {"cold": {}},
    }
    stream = inst.demand.sample(rng, targets)
    rng = np.random.default_rng([seed, 1])
    shift_stream = inst.demand.sample(rng, SHIFT_AT) + inst.shifted.sample(rng, max(AFTER_SHIFT))
    for name, marks, seq, sites, matrix, demand, optimum in (
        (
            "cold",
            {k: str(k) for k in CHECKPOINTS if k <= targets},
            stream,
            inst.sites,
            inst.matrix,
            inst.demand,
            inst.optimum[0],
        ),
        (
            "shift",
            {SHIFT_AT + k: f"+{k}" for k in AFTER_SHIFT},
            shift_stream,
            inst.shifted_sites,
            inst.shifted_matrix,
            inst.shifted,
            inst.shifted_optimum[0],
        ),
    ):
        index = {z: j for j, z in enumerate(demand.positions)}
        for k, label in marks.items():
            counts = Counter(seq[:k])
            seen = list(counts)
            weights = np.array([counts[z] for z in seen], dtype=np.float64)
            if all(z in index for z in seen):
                costs = matrix[:, np.array([index[z] for z in seen])]
            else:  # targets of the demand before the shift: priced from the same sites
                costs = inst.space.cost_matrix(sites, seen)
            out["demand_sites"][name][label] = gap(
                inst.space, _batch_answer(costs, weights, n, sites), demand, optimum
            )
            own = targets_batch_answer(inst.space, seq[:k], n)
            out[name][label] = gap(inst.space, own, demand, optimum)
            if name == "cold":
                out["sample_costs"]["cold"][label] = sample_cost(inst.space, own, seq[:k])
    return out


def targets_batch_answer(space: RoadSpace, targets: list[NetPosition], n: int) -> list[NetPosition]:
    """The p-median of ``targets`` (their empirical distribution) over their own candidate
    sites, the targets and the edge ends (:func:`solve_demand`'s, at most
    :data:`MAX_SITES`), by the heuristic: the batch answer of the targets seen."""
    seen = DemandDistribution.of_targets("seen", targets)
    return solve_demand(space, seen, n, method="heuristic").positions


def _batch_answer(
    costs: Any, weights: FloatArray, n: int, sites: list[NetPosition]
) -> list[NetPosition]:
    """The best p-median found of the targets weighted by ``weights``, from ``sites``."""
    solution = solve_pmedian(np.asarray(costs, dtype=np.float64), weights, n, method="heuristic")
    return [sites[i] for i in solution.sites]


Job = tuple[str, int, int, tuple[str, ...], tuple[str, ...], int, str, float | None, CostKind, bool]


def degenerate(inst: Instance, n: int) -> str | None:
    """Why relative gaps of ``inst`` would mean nothing, or ``None``.

    That is when its optimum costs 0 or less than :data:`DEGENERATE_FRACTION` of the
    optimum of one vehicle: ``n`` vehicles stand on (nearly) every demand atom, so that
    a fraction of a metre a target reads as a gap of many per cent.
    """
    demand = inst.demand.coarse if isinstance(inst.demand, ContinuousDemand) else inst.demand
    one = solve_demand(inst.space, demand, 1, sites=inst.sites).objective
    if inst.optimum[0] > 0.0 and inst.optimum[0] >= DEGENERATE_FRACTION * one:
        return None
    return (
        f"the optimum of {n} vehicles ({inst.optimum[0]:.3g} a target) is under "
        f"{DEGENERATE_FRACTION:.1%} of one vehicle's ({one:.3g}): they stand on nearly "
        "every demand atom"
    )


def refuse_degenerate(inst: Instance, net: str, n: int) -> None:
    """Raise :class:`InvalidInput` where :func:`degenerate` finds a reason."""
    reason = degenerate(inst, n)
    if reason is not None:
        raise InvalidInput(
            f"{network_name(net)}/{n}: {reason}: there is no relative gap to measure"
        )


def job(args: Job) -> dict[str, Any]:
    net, n, seed, rules, scenarios, targets, spec, spread, cost, anywhere = args
    t0 = time.perf_counter()
    record: dict[str, Any] = {
        "demand": spec,
        "spread": spread,
        "cost": cost,
        "anywhere": anywhere,
        "network": network_name(net),
        "vehicles": n,
        "seed": seed,
    }
    try:  # e.g. more vehicles than the network has candidate sites
        inst = instance(net, n, seed, spec, spread, cost, anywhere=anywhere)
    except InvalidInput as e:
        reason: str | None = str(e)
    else:
        record |= {
            "edges": inst.space.network.n_edges,
            "atoms": len(inst.demand.positions),
            "optimum": inst.optimum[0],
        }
        reason = degenerate(inst, n)
    record["rules"] = {}
    if reason is not None:
        print(f"{network_name(net)} n={n} seed={seed}: not measured, {reason}", file=sys.stderr)
        return {**record, "not_measured": reason}
    for rule in rules:
        record["rules"][rule] = {
            scenario: run_rule(inst, rule, scenario, n, seed, targets) for scenario in scenarios
        }
    record["anchor"] = anchor_gaps(inst, n, seed, targets)
    record["seconds"] = time.perf_counter() - t0
    print(
        f"{network_name(net)} n={n} seed={seed}: {record['seconds']:.0f} s",
        file=sys.stderr,
        flush=True,
    )
    return record


def summarise(records: list[dict[str, Any]], rules: tuple[str, ...]) -> dict[str, Any]:
    """Medians over seeds per network, size, rule, scenario and checkpoint; the worst network.

    Records of instances not measured (:func:`job`) are left out; ``"not_measured"``
    lists them.
    """
    groups: dict[tuple[str, int], list[dict[str, Any]]] = {}
    for r in records:
        if "not_measured" not in r:
            groups.setdefault((r["network"], r["vehicles"]), []).append(r)
    table: dict[str, Any] = {}
    for (net, n), rs in sorted(groups.items()):
        entry: dict[str, Any] = {}
        for rule in rules:
            entry[rule] = {}
            for scenario in rs[0]["rules"][rule]:
                labels = rs[0]["rules"][rule][scenario]["gaps"]
                entry[rule][scenario] = {
                    label: statistics.median(x["rules"][rule][scenario]["gaps"][label] for x in rs)
                    for label in labels
                }
            if "cold" in rs[0]["rules"][rule]:  # each seed against its own stream's batch answer
                for key, anchors in (
                    ("behind_anchor_paired", [x["anchor"] for x in rs]),
                    ("behind_demand_site_anchor_paired", [x["anchor"]["demand_sites"] for x in rs]),
                ):
                    entry[rule][key] = {
                        label: statistics.median(
                            x["rules"][rule]["cold"]["gaps"][label] - a["cold"][label]
                            for x, a in zip(rs, anchors, strict=True)
                        )
                        for label in rs[0]["rules"][rule]["cold"]["gaps"]
                        if label in anchors[0]["cold"]
                    }
                if all(
                    "sample_costs" in x["rules"][rule]["cold"] and "sample_costs" in x["anchor"]
                    for x in rs
                ):  # records from before the fits were kept have none
                    entry[rule]["fit_behind_anchor_paired"] = {
                        label: statistics.median(
                            x["rules"][rule]["cold"]["sample_costs"][label]
                            / x["anchor"]["sample_costs"]["cold"][label]
                            - 1.0
                            for x in rs
                        )
                        for label in rs[0]["rules"][rule]["cold"]["sample_costs"]
                    }
            for measure in ("microseconds_per_target", "step_microseconds_per_target"):
                entry[rule][measure] = statistics.median(
                    statistics.mean(s[measure] for s in x["rules"][rule].values()) for x in rs
                )
        for key, anchors in (
            ("anchor", [x["anchor"] for x in rs]),
            ("demand_site_anchor", [x["anchor"]["demand_sites"] for x in rs]),
        ):
            entry[key] = {
                scenario: {
                    label: statistics.median(a[scenario][label] for a in anchors)
                    for label in anchors[0][scenario]
                }
                for scenario in ("cold", "shift")
            }
        table[f"{net}/{n}"] = entry
    worst: dict[str, Any] = {}
    for rule in rules:
        worst[rule] = {}
        for scenario in ("cold", "warm", "shift"):
            labels = {lab for e in table.values() for lab in e[rule].get(scenario, {})}
            worst[rule][scenario] = {
                label: max(
                    (e[rule][scenario][label], key)
                    for key, e in table.items()
                    if label in e[rule].get(scenario, {})
                )
                for label in sorted(labels, key=lambda s: int(s.lstrip("+")))
            }
    left_out = [
        {
            "network": r["network"],
            "vehicles": r["vehicles"],
            "seed": r["seed"],
            "why": r["not_measured"],
        }
        for r in records
        if "not_measured" in r
    ]
    return {"median_over_seeds": table, "worst_network": worst, "not_measured": left_out}


def goals(summary: dict[str, Any], rule: str, baseline: str) -> dict[str, Any]:
    """Each goal of the learning issue for ``rule``: the worst network's median, met or not."""
    table = summary["median_over_seeds"]

    def values(scenario: str, first: int = 0) -> list[tuple[float, str]]:
        return [
            (v, f"{key}@{label}")
            for key, e in table.items()
            for label, v in e[rule].get(scenario, {}).items()
            if int(label.lstrip("+")) >= first
        ]

    def at(scenario: str, label: str) -> list[tuple[float, str]]:
        return [(v, w) for v, w in values(scenario) if w.endswith("@" + label)]

    measured: dict[str, tuple[list[tuple[float, str]], float]] = {
        "cold_3000": (at("cold", "3000"), GOALS["cold"]["3000"]),
        "cold_30000": (at("cold", "30000"), GOALS["cold"]["30000"]),
        "warm_every_checkpoint": (values("warm"), GOALS["warm_every"]),
        "warm_from_3000": (values("warm", 3000), GOALS["warm_from_3000"]),
        "shift_plus_5000": (at("shift", "+5000"), GOALS["shift_5000"]),
        **{
            f"behind_{anchor}_from_1000": (
                [
                    (v - table[w.split("@")[0]][anchor]["cold"][w.split("@")[1]], w)
                    for v, w in values("cold", 1000)
                    if w.split("@")[1] in table[w.split("@")[0]][anchor]["cold"]
                ],
                GOALS["anchor_points"],
            )
            for anchor in ("anchor", "demand_site_anchor")
        },
        **{
            f"behind_{anchor}_paired_from_1000": (
                [
                    (v, f"{key}@{label}")
                    for key, e in table.items()
                    for label, v in e[rule].get(f"behind_{anchor}_paired", {}).items()
                    if int(label) >= 1000
                ],
                GOALS["anchor_points"],
            )
            for anchor in ("anchor", "demand_site_anchor")
        },
        f"compute_ratio_to_{baseline}": (
            [
                (e[rule]["microseconds_per_target"] / e[baseline]["microseconds_per_target"], k)
                for k, e in table.items()
                if baseline in e
            ],
            GOALS["compute_ratio"],
        ),
        f"step_compute_ratio_to_{baseline}": (
            [
                (
                    e[rule]["step_microseconds_per_target"]
                    / e[baseline]["step_microseconds_per_target"],
                    k,
                )
                for k, e in table.items()
                if baseline in e
            ],
            GOALS["compute_ratio"],
        ),
    }
    out: dict[str, Any] = {}
    for name, (found, limit) in measured.items():
        if found:
            value, where = max(found)
            out[name] = {"worst": value, "where": where, "goal": limit, "met": value <= limit}
    return out


def fit_diagnostic(summary: dict[str, Any], rule: str) -> dict[str, Any] | None:
    """How much more the rule's references cost on the targets seen than the batch answer's
    (:func:`sample_cost`, paired per seed, relative; median over seeds), the worst network
    from 1,000 targets on: at most 0 where the rule fits the targets as well as a batch
    solve of them, so that a gap behind the batch answer is the spread of equally good
    fits of a sample, not a worse fit. ``None`` without the fits."""
    found = [
        (v, f"{key}@{label}")
        for key, e in summary["median_over_seeds"].items()
        for label, v in e[rule].get("fit_behind_anchor_paired", {}).items()
        if int(label) >= 1000
    ]
    if not found:
        return None
    value, where = max(found)
    return {"worst": value, "where": where}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def live_service(net: str) -> Iterator[httpx.Client]:
    """A client of a live ``routing-svc serve`` of network ``net`` (in a folder of its own,
    its banner on standard error), stopped on leaving."""
    port = free_port()
    folder = Path(tempfile.mkdtemp(prefix="learning-rest-"))
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "routing_svc.cli",
            "serve",
            "--port",
            str(port),
            "--db",
            str(folder / "events.db"),
            "--data-dir",
            str(folder),
            "--net",
            f"{network_name(net)}={network_file(net)}",
            "--no-demo",
            "--log-level",
            "warning",
        ],
        env=os.environ.copy(),
        stdout=sys.stderr,  # the server's banner must not mix with this script's JSON
    )
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=120.0) as client:
            for _ in range(600):
                try:
                    if client.get("/healthz").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                time.sleep(0.1)
            yield client
    finally:
        server.terminate()
        server.wait(timeout=30)


def wire(network: CompiledNetwork, z: NetPosition) -> dict[str, Any]:
    """A position as the API takes it."""
    return {"edge": network.edge_ids[z.edge], "offset": z.offset}


def rest_positions(
    client: httpx.Client, fleet_id: str, network: CompiledNetwork
) -> list[NetPosition]:
    """A fleet's references as ``GET /v1/fleets/{id}`` gives them, in its vehicle order."""
    fleet = client.get(f"/v1/fleets/{fleet_id}").json()
    return [
        NetPosition(network.edge_index[v["position"]["edge"]], float(v["position"]["offset"]))
        for v in fleet["vehicles"]
    ]


def rest_run(
    net: str,
    network: CompiledNetwork,
    fleet: dict[str, Any],
    targets: list[dict[str, Any]],
    checkpoints: Sequence[int],
    gap_of: Callable[[list[NetPosition]], float],
) -> dict[str, Any]:
    """Create ``fleet`` (a ``POST /v1/fleets`` body) on a live service of ``net`` (compiled
    as ``network``), post
    ``targets`` (target bodies) through ``targets:batch``, 500 a request, and at each
    checkpoint price its references by ``gap_of``: its rule, the gaps and targets/s."""
    with live_service(net) as client:
        client.post("/v1/fleets", json=fleet).raise_for_status()
        route = f"/v1/fleets/{fleet['id']}"
        gaps: dict[str, float] = {}
        done = 0
        t0 = time.perf_counter()
        for mark in [k for k in checkpoints if k <= len(targets)]:
            for lo in range(done, mark, 500):
                batch = targets[lo : min(mark, lo + 500)]
                client.post(f"{route}/targets:batch", json={"targets": batch}).raise_for_status()
            done = mark
            gaps[str(mark)] = gap_of(rest_positions(client, fleet["id"], network))
        seconds = time.perf_counter() - t0
        rule = client.get(route).json()["rule"]
    return {"rule": rule, "gaps": gaps, "targets_per_second": len(targets) / seconds}


def rest_curve(
    net: str,
    n: int,
    seed: int,
    targets: int,
    spec: str,
    spread: float | None,
    cost: CostKind,
    anywhere: bool = False,
) -> dict[str, Any]:
    """The cold curve of the default rule through a live ``routing-svc serve``."""
    inst = instance(net, n, seed, spec, spread, cost, anywhere=anywhere)
    refuse_degenerate(inst, net, n)
    space = inst.space
    network = space.network
    vehicles = [
        {"id": f"v{i:03d}", "position": wire(network, p)} for i, p in enumerate(inst.random_start)
    ]
    fleet = {"id": "bench", "network": network_name(net), "cost": cost, "vehicles": vehicles}
    stream = inst.demand.sample(np.random.default_rng([seed, 1]), targets)
    bodies = [{"position": wire(network, z)} for z in stream]

    def gap_of(positions: list[NetPosition]) -> float:
        return gap(space, positions, inst.demand, inst.optimum[0])

    run = rest_run(net, network, fleet, bodies, CHECKPOINTS, gap_of)
    return {"network": network_name(net), "vehicles": n, "seed": seed, **run}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--nets",
        default=",".join(NETWORKS),
        help="comma-separated: known names, or NAME=FILE for any SUMO network "
        f"(default {','.join(NETWORKS)})",
    )
    p.add_argument("--vehicles", default="8,20")
    p.add_argument("--seeds", default="0,1,2,3,4")
    p.add_argument("--rules", default="consolidating,paper,probe")
    p.add_argument("--scenarios", default="cold,warm,shift")
    p.add_argument("--targets", type=int, default=max(CHECKPOINTS))
    p.add_argument(
        "--demand",
        default=DEFAULT_DEMAND,
        help="where targets are, as simulate's --demand (default hotspots:3); a shift needs "
        "hotspots",
    )
    p.add_argument(
        "--spread",
        type=float,
        help="the hotspots' standard deviation as a fraction of the network's diagonal "
        "(default 0.1)",
    )
    p.add_argument(
        "--cost",
        choices=("length", "time"),
        default="length",
        help="shortest-path cost of every fleet: metres or free-flow travel time (default length)",
    )
    p.add_argument(
        "--anywhere",
        action="store_true",
        help="targets anywhere along the road, not at the demand's atoms (each gap integrated "
        "exactly along the demand's pieces of road)",
    )
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--rest", action="store_true", help="add one curve through the REST API")
    p.add_argument("--out", type=Path, help="also write the JSON here")
    p.add_argument(
        "--records", type=Path, help="append each finished job's record here (JSON lines)"
    )
    p.add_argument(
        "--summarise",
        type=Path,
        nargs="*",
        metavar="RECORDS",
        help="only summarise records written by --records (one or more files)",
    )
    args = p.parse_args()
    rules = tuple(Rule(r).value for r in args.rules.split(","))
    scenarios = tuple(args.scenarios.split(","))
    nets = args.nets.split(",")
    refuse_unknown(p, nets, [args.demand])
    form = parse_demand_spec(args.demand).form
    if args.spread is not None and not (math.isfinite(args.spread) and args.spread > 0.0):
        p.error("--spread must be a fraction > 0")
    if "shift" in scenarios and not isinstance(form, Hotspots):
        p.error(f"a shift moves hotspots; --demand {args.demand} has none (--scenarios cold,warm)")
    demand = (args.demand, args.spread, args.cost, args.anywhere)
    work: list[Job] = [
        (net, int(n), int(seed), rules, scenarios, args.targets, *demand)
        for net in nets
        for n in args.vehicles.split(",")
        for seed in args.seeds.split(",")
    ]
    started = time.perf_counter()
    records: list[dict[str, Any]] = []
    if args.summarise is not None:
        for path in args.summarise:
            records += [json.loads(line) for line in path.read_text().splitlines() if line]
        rules = tuple(r for r in rules if all(r in x["rules"] for x in records))
    else:
        with ProcessPoolExecutor(args.jobs) as pool:
            for record in pool.map(job, work):
                records.append(record)
                if args.records:
                    with args.records.open("a") as out:
                        out.write(json.dumps(record) + "\n")
    summary = summarise(records, rules)
    report: dict[str, Any] = {
        "benchmark": "learning",
        "demand": args.demand
        if args.summarise is None
        else sorted({r.get("demand", DEFAULT_DEMAND) for r in records}),
        "spread": args.spread,
        "cost": args.cost,
        "anywhere": args.anywhere,
        "baseline": {"compute": "probe (the compiled update of the rule before)"},
        "checkpoints": list(CHECKPOINTS),
        "shift": {"at": SHIFT_AT, "after": list(AFTER_SHIFT)},
        "optimum": f"best p-median found over at most {MAX_SITES} candidate sites",
        "goals": {rule: goals(summary, rule, "probe") for rule in rules},  # ratios need probe
        "fit_behind_anchor_paired_from_1000": {
            rule: fit_diagnostic(summary, rule) for rule in rules
        },
        **summary,
    }
    report = finished(report, records, started)
    if args.rest:
        report["rest"] = rest_curve(
            nets[0],
            int(args.vehicles.split(",")[0]),
            0,
            args.targets,
            args.demand,
            args.spread,
            args.cost,
            args.anywhere,
        )
    text = json.dumps(report, indent=1)
    if args.out:
        args.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
