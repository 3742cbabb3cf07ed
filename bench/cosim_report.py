"""Generate the co-simulation report: ``python bench/cosim_report.py``.

Runs every experiment of the report in SUMO (libsumo, ``--workers`` parallel
processes), then writes ``docs/cosim.md``, its figures under
``docs/figures/cosim/`` and ``docs/figures/cosim/report.json`` (every
summary). SUMO's inputs and outputs go to ``--workdir``; runs already saved
there for the same options are reused (``--no-resume`` runs everything
again), so an interrupted report continues where it stopped.

Experiments: SUMO's DRT district (``<SUMO_HOME>/tools/game/DRT/osm.net.xml``)
and Bad Hersfeld (``../shared/nets/badhersfeld.net.xml.gz`` beside the
checkout; skipped with a note if absent), 10 and 20 vehicles, persons and
incidents; Bad Hersfeld saturated (10 vehicles, 1.5 times the request rate)
and with demand from its buildings (``badhersfeld.buildings.csv``). Each
experiment compares ``sa``, ``sa-available``, ``optimum``, ``sumo-stop`` and
``sumo-taxistand`` on identical demand and checks the goals of the live
operations issue: ``sa``'s mean wait at most 0.8 times ``sumo-stop``'s, its
90th-percentile wait at most 0.8 times ``sumo-stop``'s, and its mean wait at
most 1.05 times ``optimum``'s. 3 seeds by default (``--seeds 0,1,2``);
``--only`` picks experiments. The sections measured with commands of their
own (``bench/cosim_sections/*.md``) are appended as they are written.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from bench_shared import SHARED

from routing_svc.json_text import json_text
from routing_svc.sim import CosimResult, CosimSpec, PolicyRun, parse_policies, run_cosim
from routing_svc.sim.command import parse_seeds
from routing_svc.sim.measures import DEFAULT_THRESHOLDS
from routing_svc.sim.plots import FIGURE_KINDS, figure_path, write_figures
from routing_svc.sim.spec import DEFAULT_INCIDENT_SAMPLE

ROOT = Path(__file__).resolve().parent.parent
BADHERSFELD = SHARED / "badhersfeld.net.xml.gz"
BUILDINGS = SHARED / "badhersfeld.buildings.csv"
FIGURES = ROOT / "docs" / "figures" / "cosim"
POLICIES = "sa,sa-available,optimum,sumo-stop,sumo-closest,sumo-taxistand"

#: The goals: (name, statistic, baseline policy, largest ratio of the policy's to the baseline's).
GOALS = (
    ("mean ≤ 0.8 x sumo-stop", "mean_wait_s", "sumo-stop", 0.8),
    ("p90 ≤ 0.8 x sumo-stop", "p90_wait_s", "sumo-stop", 0.8),
    ("mean ≤ 1.05 x optimum", "mean_wait_s", "optimum", 1.05),
)

#: Request rate of the saturated experiment, as a multiple of the base rate.
SATURATED_FACTOR = 1.5


@dataclass(frozen=True)
class Experiment:
    """One experiment of the report."""

    key: str
    title: str
    spec: CosimSpec


def experiments(
    *,
    seeds: Sequence[int],
    hours: float,
    rate: float,
    history: int,
    workers: int,
    rule: str | None = None,
) -> list[Experiment]:
    """Every experiment of the full report, in order (``rule``: the fleets' learning rule,
    ``None`` for the service's default)."""
    base = CosimSpec(
        network="drt",
        duration=hours * 3600.0,
        rate=rate,
        history=history,
        seeds=tuple(seeds),
        workers=workers,
        policies=parse_policies(POLICIES),
        rule=rule,
    )
    networks = {"drt": ("drt", 20.0)}
    if BADHERSFELD.is_file():
        networks["badhersfeld"] = (str(BADHERSFELD), 3.0)
    out = []
    for name, (net, density) in networks.items():
        for mode in ("persons", "incidents"):
            for vehicles in (10, 20):
                spec = replace(base, network=net, density=density, vehicles=vehicles, mode=mode)
                out.append(
                    Experiment(
                        f"{name}-{mode}-{vehicles}", f"{name}, {mode}, {vehicles} vehicles", spec
                    )
                )
        if name == "badhersfeld":
            busy = replace(
                base, network=net, density=density, vehicles=10, rate=rate * SATURATED_FACTOR
            )
            out.append(
                Experiment(
                    f"{name}-saturated-10",
                    f"{name}, persons, 10 vehicles, saturated ({busy.rate:g} requests/h)",
                    busy,
                )
            )
            if BUILDINGS.is_file():
                homes = replace(
                    base, network=net, density=density, vehicles=10, demand=f"buildings:{BUILDINGS}"
                )
                out.append(
                    Experiment(
                        f"{name}-buildings-10",
                        f"{name}, persons from the buildings, 10 vehicles",
                        homes,
                    )
                )
    return out


# -- figures per policy --------------------------------------------------------


def _mean(values: Sequence[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return float(np.mean(finite)) if finite else math.nan


def _sd(values: Sequence[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.std(finite, ddof=1)) if len(finite) > 1 else 0.0


def policy_figures(runs: Sequence[PolicyRun]) -> dict[str, Any]:
    """Means over the seeds of one policy's runs (the statistics the report shows)."""
    summaries = [r.summary() for r in runs]
    thresholds = [f"{t:g}" for t in runs[0].thresholds] if runs else []
    return {
        "seeds": len(runs),
        "mean_wait_s": _mean([s["mean_wait_s"] for s in summaries]),
        "mean_wait_sd_s": _sd([s["mean_wait_s"] for s in summaries]),
        "p90_wait_s": _mean([s["p90_wait_s"] for s in summaries]),
        "within": {t: _mean([s["within"][t] for s in summaries]) for t in thresholds},
        "empty_km": _mean([s["empty_km"] for s in summaries]),
        "requests_per_vehicle_hour": _mean([s["requests_per_vehicle_hour"] for s in summaries]),
        "busy_fraction": _mean([s["busy_fraction"] for s in summaries]),
        "requests": sum(s["requests"] for s in summaries),
        "served": sum(s["served"] for s in summaries),
        "queued": sum(s["queued"] for s in summaries),
        "fallbacks": sum(s["fallbacks"] for s in summaries),
        "lost": sum(s["lost"] for s in summaries),
        "wall_seconds": sum(s["wall_seconds"] for s in summaries),
        "sim_seconds": sum(s["sim_seconds"] for s in summaries),
    }


def goal_checks(figures: dict[str, dict[str, Any]], policy: str = "sa") -> list[dict[str, Any]]:
    """Each goal of :data:`GOALS` for ``policy``: ratio, whether met, and the shortfall.

    ``shortfall_s`` is how many seconds ``policy``'s statistic is above what the
    goal allows (0 when met); ``None`` when a policy is missing.
    """
    checks = []
    for name, statistic, baseline, limit in GOALS:
        mine = figures.get(policy, {}).get(statistic, math.nan)
        theirs = figures.get(baseline, {}).get(statistic, math.nan)
        ratio = mine / theirs if theirs and math.isfinite(theirs) else math.nan
        allowed = limit * theirs
        met = bool(math.isfinite(ratio) and ratio <= limit)
        checks.append(
            {
                "goal": name,
                "policy": policy,
                "ratio": ratio,
                "limit": limit,
                "met": met,
                "shortfall_s": None if not math.isfinite(ratio) else max(mine - allowed, 0.0),
            }
        )
    return checks


# -- markdown --------------------------------------------------------------------


def _num(value: float, fmt: str = ".0f") -> str:
    if math.isnan(value):
        return "n/a"
    if math.isinf(value):
        return "∞"
    return format(value, fmt)


def _check_text(check: dict[str, Any]) -> str:
    ratio = check["ratio"]
    if not math.isfinite(ratio):
        return "n/a"
    if check["met"]:
        return f"{ratio:.3f} met"
    return f"{ratio:.3f} **missed** by {check['shortfall_s']:.0f} s"


def _table(figures: dict[str, dict[str, Any]]) -> list[str]:
    thresholds = next(iter(figures.values()))["within"].keys() if figures else []
    several = any(row["seeds"] > 1 for row in figures.values())
    head = " | ".join(f"≤ {t} s" for t in thresholds)
    lines = [
        f"| policy | mean wait (s){' ± sd over seeds' if several else ''} | p90 wait (s) "
        f"| {head} | empty km | requests/vehicle-h "
        "| busy | served | queued |",
        "|---|---|---|" + "---|" * len(thresholds) + "---|---|---|---|---|",
    ]
    for name, row in figures.items():
        within = " | ".join(_num(100.0 * row["within"][t], ".0f") + "%" for t in thresholds)
        spread = f" ± {_num(row['mean_wait_sd_s'])}" if row["seeds"] > 1 else ""
        lost = f" ({row['lost']} vehicle(s) left SUMO)" if row["lost"] else ""
        lines.append(
            f"| {name} | {_num(row['mean_wait_s'])}{spread} "
            f"| {_num(row['p90_wait_s'])} | {within} | {_num(row['empty_km'], '.1f')} "
            f"| {_num(row['requests_per_vehicle_hour'], '.2f')} "
            f"| {_num(100.0 * row['busy_fraction'])}% | {row['served']}/{row['requests']}{lost} "
            f"| {row['queued']} |"
        )
    return lines


def _why(figures: dict[str, dict[str, Any]], checks: list[dict[str, Any]]) -> list[str]:
    """Figures that explain a missed goal: load, queueing and the other policies."""
    if all(c["met"] for c in checks):
        return []
    sa = figures.get("sa", {})
    stop = figures.get("sumo-stop", {})
    stand = figures.get("sumo-taxistand", {})
    optimum = figures.get("optimum", {})
    notes = [
        f"- Load: {_num(sa.get('requests_per_vehicle_hour', math.nan), '.2f')} requests per "
        f"vehicle-hour; `sa`'s vehicles were busy {_num(100 * sa.get('busy_fraction', math.nan))}% "
        f"of the time and {sa.get('queued', 0)} of its {sa.get('requests', 0)} requests found "
        "nobody available and waited in the queue.",
        f"- `optimum` (same dispatch, references at the p-median): mean "
        f"{_num(optimum.get('mean_wait_s', math.nan))} s, p90 "
        f"{_num(optimum.get('p90_wait_s', math.nan))} s; `sumo-taxistand` (SUMO's dispatch, "
        f"stands at the same sites): mean {_num(stand.get('mean_wait_s', math.nan))} s; "
        f"`sumo-stop`: mean {_num(stop.get('mean_wait_s', math.nan))} s, p90 "
        f"{_num(stop.get('p90_wait_s', math.nan))} s."
        + (
            " Even `optimum`'s references miss a `sumo-stop` goal here: with this dispatch "
            "the gap is not where the references are."
            if not all(c["met"] for c in goal_checks(figures, "optimum")[:2])
            else ""
        ),
        f"- Empty km: `sa` {_num(sa.get('empty_km', math.nan), '.1f')}, `sumo-stop` "
        f"{_num(stop.get('empty_km', math.nan), '.1f')} (the service's vehicles drive back to "
        "their references after each ride).",
    ]
    return notes


def _where_references_stand(
    figures: dict[str, dict[str, Any]], checks: list[dict[str, Any]], history: int
) -> list[str]:
    """Where ``sa``'s mean misses ``optimum``'s goal (``checks[2]``): how far its references
    are from ``optimum``'s by the demand's expected free-flow wait, beside the seeds' spread."""
    sa, optimum = figures.get("sa", {}), figures.get("optimum", {})
    if checks[2]["met"] or not all(
        math.isfinite(row.get("expected_wait_s", math.nan)) for row in (sa, optimum)
    ):
        return []
    expected, best = sa["expected_wait_s"], optimum["expected_wait_s"]
    measured, measured_best = sa["mean_wait_s"], optimum["mean_wait_s"]
    return [
        f"- Where the references stand: the demand's expected free-flow wait is "
        f"{expected:.1f} s from `sa`'s references at the end of the run and {best:.1f} s "
        f"from `optimum`'s ({100 * (expected / best - 1):+.1f} %); `sa` started at the "
        f"p-median of its {history} historical requests. The measured means differ by "
        f"{100 * (measured / measured_best - 1):+.1f} %, with standard deviations over "
        f"the seeds of {_num(sa['mean_wait_sd_s'])} s (`sa`) and "
        f"{_num(optimum['mean_wait_sd_s'])} s (`optimum`)."
    ]


def section(experiment: Experiment, figures: dict[str, dict[str, Any]], pictures: Any) -> list[str]:
    """One experiment's part of the document."""
    spec = experiment.spec
    lines = [f"### {experiment.title}", ""]
    lines.append(
        f"Seeds {', '.join(map(str, spec.seeds))}; {spec.duration / 3600:g} h of requests at "
        f"{spec.rate:g}/h ({spec.demand if spec.mode == 'persons' else 'incidents'}) after "
        f"{spec.warmup / 60:g} min of traffic, {spec.drain / 60:g} min to finish; background "
        f"traffic {spec.density:g} vehicles/h/km."
    )
    lines += ["", *_table(figures), ""]
    for policy in ("sa", "sa-available"):
        if policy not in figures:
            continue
        checks = goal_checks(figures, policy)
        lines.append(
            f"- Goals for `{policy}`: "
            + "; ".join(f"{c['goal']}: {_check_text(c)}" for c in checks)
            + "."
        )
    checks = goal_checks(figures)
    lines += _why(figures, checks)
    lines += _where_references_stand(figures, checks, spec.history)
    if spec.mode == "incidents" and not checks[2]["met"]:
        lines.append(
            f"- For incidents `optimum`'s references are the p-median of {spec.incident_sample} "
            "incidents recorded in the same traffic as the run (apart from the ones served); "
            f"`sa` learnt from {spec.history} incidents recorded in another traffic realisation."
        )
    lines.append("")
    for kind, path in pictures.items():
        rel = path.relative_to(ROOT / "docs")
        lines.append(f"![{experiment.key} {kind}]({rel.as_posix()})")
    lines.append("")
    return lines


def headline(all_figures: dict[str, dict[str, dict[str, Any]]]) -> list[str]:
    """One row per experiment: the mean waits and the goals of ``sa``."""
    names = POLICIES.split(",")
    lines = [
        "| experiment | " + " | ".join(names) + " | sa p90 / sumo-stop p90 | load (req/veh-h, "
        "sa busy) | goals met (sa) |",
        "|---|" + "---|" * len(names) + "---|---|---|",
    ]
    for key, figures in all_figures.items():
        waits = " | ".join(_num(figures.get(n, {}).get("mean_wait_s", math.nan)) for n in names)
        checks = goal_checks(figures)
        sa = figures.get("sa", {})
        p90 = checks[1]["ratio"]
        lines.append(
            f"| {key} | {waits} | {_num(p90, '.3f')} "
            f"| {_num(sa.get('requests_per_vehicle_hour', math.nan), '.2f')}, "
            f"{_num(100 * sa.get('busy_fraction', math.nan))}% "
            f"| {sum(c['met'] for c in checks)}/{len(checks)} |"
        )
    return lines


INTRO = """# Co-simulation with SUMO: the fleet service's dispatch against SUMO's own taxis

Generated by `{command}` ({runtime}). Seeds: {seeds}. Every number below comes from that
command; the full report is `python bench/cosim_report.py` (3 seeds). {figures}All
summaries: `docs/figures/cosim/report.json`.

## What runs

- **SUMO makes the traffic and the demand and measures the outcome.** Background traffic
  is SUMO's `randomTrips.py`. Requests are SUMO persons who ask for a taxi ride (SUMO's
  taxi device and reservations); rides end within 1.5 km.
  - `persons`: places drawn from a 3-hotspot mixture over the car network, or (the
    `buildings` experiment) from the buildings of Bad Hersfeld
    (`--demand buildings:../shared/nets/badhersfeld.buildings.csv`), Poisson times.
  - `incidents`: at Poisson times, the place of a random background vehicle, recorded in
    a SUMO run of the background traffic alone, so every policy sees the same incidents.
- **Policies on identical requests** (same seed, same persons file):
  - `sa`: this product. For each request the co-simulation posts a target to the fleet
    service (`POST .../targets`): the fleet records it (its rule decides when references
    move, below), and SUMO sends the vehicles named
    in the answer's `dispatch` block (the closest *available* vehicles by their current
    positions and the service's travel times). The co-simulation reports every state
    change SUMO makes to the service (`POST .../vehicles/state:batch`, one batch per
    simulation step): `busy` at dispatch, `available` with the current position at the
    drop-off, the positions of available vehicles that drive to their posts (every 30 s
    while they move). An answer `queued` (nobody available) puts the request in a
    queue; at each drop-off the queue is served first, asking `POST .../assign` again
    (read-only) for every waiting request: the freed vehicle goes to the one the service
    says it reaches soonest, except that a request waiting 900 s or more (the largest
    service-level threshold) goes first, oldest first (`--queue soonest`, the
    co-simulation's default; `--queue fifo` serves the oldest). Serving the nearest
    request first shortens the empty drives, so a saturated fleet serves more requests
    an hour. Idle vehicles wait at the posts the service names (`GET .../posts`, asked
    again whenever a vehicle turns busy or available or a
    reference moves): with `k` vehicles available, the `k` references that serve the
    recent targets best, held by the available vehicles at the least total travel time
    (move-up; with every vehicle available, all the references). An idle vehicle whose
    post changes drives to the new one and parks.
    Whose reference learns is the paper's choice, `learning_vehicles=all` (the closest
    reference moves, busy or not), with the {rule} learning rule; the fleet starts at the
    p-median of {history} historical requests.
  - `sa-available`: the same with `learning_vehicles=available` (the closest reference
    among the available vehicles moves). Under the `consolidating` rule a fleet started at
    the p-median of its history has no consolidation of its own yet, and its held steps
    wait for the first one, due 250 targets into the epoch
    (`ConsolidationPolicy.first`, `unfitted_confidence`). At 40 requests an hour (60
    saturated) for one or two hours no reference moves at all: `sa` and `sa-available`
    are equal, and `sa` waits where the p-median of its {history} historical requests put it.
    What separates `sa` from `optimum` (same dispatch, same posts) in this report is that
    sample, not learning during the run (`--rule paper` compares the two choices under
    the paper's step alone).
  - `optimum`: the same dispatch, references frozen at the best-known p-median of the
    demand (for incidents: the p-median of {incident_sample} incidents recorded in the same
    traffic as the run, apart from the ones served: an estimate of the incident
    distribution, where a p-median of the served incidents themselves would place the
    vehicles with hindsight).
  - `sumo-stop`: SUMO's taxi device alone, `greedy` dispatch every second (reservations
    oldest first, each to the closest idle taxi), idle taxis stop where they dropped their
    customer.
  - `sumo-closest`: the same with SUMO's `greedyClosest` dispatch, which serves the
    reservation with the shortest travel time to pick-up first: SUMO's own counterpart
    of the queue order above, to show what the positions add beyond it. The goals
    compare with `sumo-stop`, as the issue sets them.
  - `sumo-taxistand`: SUMO's taxi device alone, `greedy` dispatch, idle algorithm
    `taxistand`: one stand (a `parkingArea` in an additional file, listed by the rerouter
    that `device.taxi.stands-rerouter` names) at each of `optimum`'s sites, where the taxis
    also start; an idle taxi drives to the closest stand (`parking.ignoreDest`).
- **Measures, all from SUMO.** A request's wait is the `waitingTime` of the person's
  `<ride>` in SUMO's personinfo output (request to pick-up). Service levels are over every
  request of the measured period: the 90th percentile (nearest rank) and the fraction
  served within the fleet's thresholds ({thresholds} s); a request never served counts as
  an infinite wait (`null` in the JSON). Empty km = the fleet's `routeLength` minus
  `occupiedDistance`. Load: requests per vehicle-hour, and the busy fraction, the share of
  SUMO taxi states sampled every 10 s in the request period that are driving to a pick-up
  or carrying a customer.
- **Goals** (issue "live operations"), per experiment, on the means over the seeds: `sa`'s
  mean wait ≤ 0.8 x `sumo-stop`'s; `sa`'s 90th-percentile wait ≤ 0.8 x `sumo-stop`'s;
  `sa`'s mean wait ≤ 1.05 x `optimum`'s. A missed goal gives the ratio and how many
  seconds `sa` is above what the goal allows, with the experiment's load.

## How to run it

```
python bench/cosim_report.py                                  # everything, 3 seeds
python bench/cosim_report.py --seeds 0 --only drt-persons-10  # a part
python bench/cosim_report.py --seeds 0 --hours 1 --render-only  # this document from the runs
routing-svc cosim --net drt --vehicles 10 --hours 2 --seeds 0,1,2 --history 1000 \\
    --policies sa,sa-available,optimum,sumo-stop,sumo-closest,sumo-taxistand
```
{missing}
## Headline: mean SUMO-measured wait (s), mean of the seeds

"""


#: Sections measured with their own commands, appended after the report's runs, in order.
MEASURED_SECTIONS = (
    ROOT / "bench" / "cosim_sections" / "stands.md",
    ROOT / "bench" / "cosim_sections" / "other_networks.md",
    ROOT / "bench" / "cosim_sections" / "travel_times.md",
)


def render(
    all_figures: dict[str, dict[str, dict[str, Any]]],
    sections: list[str],
    *,
    command: str,
    seeds: Sequence[int],
    history: int,
    rule: str | None,
    left_out: list[str],
    pictures: bool,
) -> str:
    """The whole document."""
    runs = sum(p["seeds"] for f in all_figures.values() for p in f.values())
    simulated = sum(p["sim_seconds"] for f in all_figures.values() for p in f.values()) / 3600.0
    wall = sum(p["wall_seconds"] for f in all_figures.values() for p in f.values()) / 60.0
    runtime = (
        f"{runs} SUMO runs, {simulated:.0f} simulated hours, {wall:.0f} min of SUMO wall time "
        "on a shared 2-core machine"
    )
    missing = ""
    if not BADHERSFELD.is_file():
        missing += (
            "\n> Bad Hersfeld was skipped: `../shared/nets/badhersfeld.net.xml.gz` is missing.\n"
        )
    if left_out:
        missing += (
            "\n> This run leaves out these experiments of the full list: "
            + ", ".join(f"`{key}`" for key in left_out)
            + ".\n"
        )
    met = sum(c["met"] for f in all_figures.values() for c in goal_checks(f))
    total = sum(len(goal_checks(f)) for f in all_figures.values())
    text = INTRO.format(
        command=command,
        runtime=runtime,
        seeds=", ".join(map(str, seeds)),
        history=history,
        rule=f"`{rule}`" if rule else "service's default (`consolidating`)",
        figures="Figures: `docs/figures/cosim/`. " if pictures else "",
        thresholds=", ".join(f"{t:g}" for t in DEFAULT_THRESHOLDS),
        missing=missing,
        incident_sample=DEFAULT_INCIDENT_SAMPLE,
    )
    summary = [
        *headline(all_figures),
        "",
        f"`sa` meets {met} of the {total} goal checks of this run.",
        "",
        "## Results",
        "",
    ]
    measured = "".join("\n" + path.read_text(encoding="utf-8") for path in MEASURED_SECTIONS)
    return text + "\n".join(summary + sections) + measured


def drawn_figures(key: str) -> dict[str, Path]:
    """The figures a full run drew for experiment ``key`` that are still in ``FIGURES``."""
    paths = {kind: figure_path(FIGURES, key, kind) for kind in FIGURE_KINDS}
    return {kind: path for kind, path in paths.items() if path.is_file()}


def _saved_runs(out_dir: Path) -> tuple[dict[str, Any], list[PolicyRun]] | None:
    """The summary and runs an earlier report saved in ``out_dir`` (``None``: not finished)."""
    summary, runs = out_dir / "summary.json", out_dir / "runs.json"
    if not (summary.is_file() and runs.is_file()):
        return None
    saved = json.loads(runs.read_text(encoding="utf-8"))
    return (
        json.loads(summary.read_text(encoding="utf-8")),
        [PolicyRun.from_json(r) for r in saved["runs"]],
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--workdir", type=Path, default=Path.home() / ".cache" / "routing_svc" / "cosim-report"
    )
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seeds", type=parse_seeds, default=(0, 1, 2), help="comma list of seeds")
    parser.add_argument("--hours", type=float, default=2.0)
    parser.add_argument("--rate", type=float, default=40.0, help="requests per hour")
    parser.add_argument("--history", type=int, default=1000)
    parser.add_argument(
        "--rule",
        choices=["consolidating", "probe", "paper"],
        default=None,
        help="learning rule of the service's fleets (default: the service's)",
    )
    parser.add_argument("--only", default=None, help="comma list of experiment keys")
    parser.add_argument("--no-resume", action="store_true")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.add_argument(
        "--render-only",
        action="store_true",
        help="run nothing: write the report from the experiments finished in --workdir "
        "(without figures); unfinished ones are listed as left out",
    )
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    chosen = experiments(
        seeds=args.seeds,
        hours=args.hours,
        rate=args.rate,
        history=args.history,
        workers=args.workers,
        rule=args.rule,
    )
    left_out: list[str] = []
    if args.only:
        keep = {k.strip() for k in args.only.split(",") if k.strip()}
        unknown = sorted(keep - {e.key for e in chosen})
        if unknown:
            parser.error(
                f"--only: unknown experiment(s) {', '.join(unknown)}; "
                f"known: {', '.join(e.key for e in chosen)}"
            )
        left_out = [e.key for e in chosen if e.key not in keep]
        chosen = [e for e in chosen if e.key in keep]
    FIGURES.mkdir(parents=True, exist_ok=True)
    sections: list[str] = []
    report: dict[str, Any] = {}
    all_figures: dict[str, dict[str, dict[str, Any]]] = {}
    drawn = False  # whether any experiment's figures are shown
    started = time.perf_counter()
    for experiment in chosen:
        t0 = time.perf_counter()
        out_dir = args.workdir / experiment.key
        if args.render_only:
            saved = _saved_runs(out_dir)
            if saved is None:
                left_out.append(experiment.key)
                continue
            by_policy: dict[str, list[PolicyRun]] = {}
            for run in saved[1]:
                by_policy.setdefault(run.policy, []).append(run)
            summary, pictures = saved[0], drawn_figures(experiment.key)
        else:
            print(f"[cosim report] {experiment.key} ...", file=sys.stderr, flush=True)
            result: CosimResult = run_cosim(
                experiment.spec,
                out_dir=out_dir,
                progress=not args.quiet,
                resume=not args.no_resume,
            )
            by_policy = result.by_policy()
            summary = result.summary()
            pictures = (
                {}
                if args.no_figures
                else write_figures(result, out_dir=FIGURES, prefix=experiment.key)
            )
        figures = {name: policy_figures(runs) for name, runs in by_policy.items()}
        for name, row in figures.items():  # the demand's expected wait from the references
            expected = summary["policies"].get(name, {}).get("final_expected_wait_s")
            row["expected_wait_s"] = math.nan if expected is None else float(expected)
        sections += section(experiment, figures, pictures)
        drawn = drawn or bool(pictures)
        all_figures[experiment.key] = figures
        report[experiment.key] = {
            **summary,
            "figures": figures,
            "goals": {p: goal_checks(figures, p) for p in ("sa", "sa-available") if p in figures},
        }
        print(
            f"[cosim report] {experiment.key} done in {time.perf_counter() - t0:.0f} s",
            file=sys.stderr,
            flush=True,
        )
    if not report:
        parser.error(f"no experiment has finished in {args.workdir}; nothing was written")
    (FIGURES / "report.json").write_text(json_text(report, indent=2) + "\n", encoding="utf-8")
    command = "python bench/cosim_report.py --seeds " + ",".join(map(str, args.seeds))
    for option, value, default in (("--hours", args.hours, 2.0), ("--rate", args.rate, 40.0)):
        if value != default:
            command += f" {option} {value:g}"
    if args.history != 1000:
        command += f" --history {args.history}"
    if args.rule is not None:
        command += f" --rule {args.rule}"
    if args.only:
        command += f" --only {args.only}"
    text = render(
        all_figures,
        sections,
        command=command,
        seeds=args.seeds,
        history=args.history,
        rule=args.rule,
        left_out=left_out,
        pictures=drawn,
    )
    (ROOT / "docs" / "cosim.md").write_text(text, encoding="utf-8")
    print(
        f"[cosim report] wrote docs/cosim.md in {time.perf_counter() - started:.0f} s",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
