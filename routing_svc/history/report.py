"""The report of a history import: the gap to the history's p-median, service levels
by hour of day, and the reference positions before and after.

- **Gap.** The history's targets, taken as an empirical demand (each distinct
  position weighted by its number of calls), define an expected cost
  ``J(p) = sum_j w_j min_i d(p_i, z_j)**q`` (the objective of eq. (8) of Le Ny &
  Pappas with the empirical distribution). At each checkpoint the fleet's
  references are evaluated exactly (:func:`routing_svc.optimum.expected_cost`)
  and compared with the p-median of the same targets, solved by the service's
  own "sites -> costs -> p-median" helper
  (:func:`routing_svc.service.reference.solve_reference`). Vehicles count as
  identical (any one serves, speeds ignored): the p-median's objective. Beyond
  :data:`MAX_ATOMS` distinct positions the demand is a sample of calls evenly
  spaced in time.
- **Service levels.** Each call's ``cost`` is the one its target result carries
  (the travel cost of the vehicle that completed it, from its reference). Per
  hour of day: the fraction of calls with cost at most each threshold, and the
  50th/90th/95th percentiles (numpy's linear interpolation).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from routing_svc.demand import DemandDistribution
from routing_svc.history.replay import Checkpoint
from routing_svc.json_text import json_text
from routing_svc.optimum import expected_cost, gap
from routing_svc.sa import Objective
from routing_svc.service.networks import NetworkEntry
from routing_svc.service.reference import solve_reference
from routing_svc.types import NetPosition

DEFAULT_THRESHOLDS = (300.0, 600.0, 900.0)
PERCENTILES = (50, 90, 95)
MAX_ATOMS = 5_000
"""Most demand atoms the gap is computed on."""


def history_demand(targets: Sequence[NetPosition]) -> DemandDistribution[NetPosition]:
    """The empirical demand of ``targets`` (sampled evenly beyond :data:`MAX_ATOMS`
    distinct positions)."""
    chosen = list(targets)
    if len(set(chosen)) > MAX_ATOMS:
        keep = np.linspace(0, len(chosen) - 1, MAX_ATOMS).round().astype(np.int64)
        chosen = [chosen[int(i)] for i in keep]
    return DemandDistribution.of_targets("history", chosen)


def objective_power(fleet: dict[str, Any]) -> float:
    """The power ``q`` of a fleet's objective as the API describes it."""
    return Objective.parse(str(fleet["objective"]).removeprefix("power:")).power


def gap_curve(
    entry: NetworkEntry,
    *,
    cost: str,
    power: float,
    targets: Sequence[NetPosition],
    checkpoints: Sequence[Checkpoint],
) -> dict[str, Any]:
    """The fleet's exact cost on the history's demand at each checkpoint, against the
    p-median of the same demand."""
    demand = history_demand(targets)
    space = entry.space(cost)
    vehicles = len(checkpoints[0].positions)
    _, optimum = solve_reference(entry, cost=cost, demand=demand, vehicles=vehicles, power=power)
    curve = []
    for mark in checkpoints:
        positions = [
            NetPosition(entry.network.edge_index[p["edge"]], float(p["offset"]))
            for p in mark.positions
        ]
        value = expected_cost(space, positions, np.ones(vehicles), demand, power=power)
        curve.append(
            {
                "calls": mark.calls,
                "version": mark.version,
                "expected_cost": value,
                "gap": gap(value, optimum["objective"]),
            }
        )
    return {"atoms": len(demand.positions), "power": power, "optimum": optimum, "curve": curve}


def service_levels(
    costs: npt.NDArray[np.float64],
    hours: npt.NDArray[np.int64],
    *,
    thresholds: Sequence[float] = DEFAULT_THRESHOLDS,
) -> dict[str, Any]:
    """Fractions within ``thresholds`` and percentiles, overall and per hour of day."""

    def levels(values: npt.NDArray[np.float64]) -> dict[str, Any]:
        return {
            "calls": int(values.shape[0]),
            "within": {f"{t:g}": float(np.mean(values <= t)) for t in thresholds},
            **{f"p{q}": float(np.percentile(values, q)) for q in PERCENTILES},
        }

    by_hour = [{"hour": h, **levels(costs[hours == h])} for h in range(24) if np.any(hours == h)]
    return {"thresholds": list(thresholds), "all": levels(costs), "by_hour": by_hour}


def _draw_network(ax: Any, entry: NetworkEntry) -> None:
    from matplotlib.collections import LineCollection

    net = entry.network
    segments = [
        net.shape_xy[net.shape_offsets[i] : net.shape_offsets[i + 1]] for i in range(net.n_edges)
    ]
    ax.add_collection(LineCollection(segments, colors="0.75", linewidths=0.5))
    ax.set_aspect("equal")
    ax.autoscale()


def _xy(entry: NetworkEntry, positions: Sequence[dict[str, Any]]) -> npt.NDArray[np.float64]:
    space = entry.space("length")
    return np.array(
        [
            space.xy(NetPosition(entry.network.edge_index[p["edge"]], float(p["offset"])))
            for p in positions
        ]
    )


def plot_report(
    folder: Path, entry: NetworkEntry, report: dict[str, Any], checkpoints: Sequence[Checkpoint]
) -> list[Path]:
    """Write the report's three PNG plots into ``folder``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    finite = [c for c in report["gap"]["curve"] if c["gap"] is not None]  # None: optimum 0
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot([c["calls"] for c in finite], [100 * c["gap"] for c in finite], marker="o")
    ax.set_xlabel("calls replayed")
    ax.set_ylabel("gap to the history's p-median (%)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    paths.append(folder / "history_gap.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    levels = report["service_levels"]
    hours = [h["hour"] for h in levels["by_hour"]]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    for t in levels["thresholds"]:
        top.plot(
            hours, [h["within"][f"{t:g}"] for h in levels["by_hour"]], marker=".", label=f"<= {t:g}"
        )
    top.set_ylabel("fraction of calls")
    top.set_ylim(0, 1.02)
    top.legend(fontsize=8)
    for q in PERCENTILES:
        bottom.plot(hours, [h[f"p{q}"] for h in levels["by_hour"]], marker=".", label=f"p{q}")
    bottom.set_ylabel("cost")
    bottom.set_xlabel("hour of day")
    bottom.legend(fontsize=8)
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    paths.append(folder / "history_service_levels.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 6))
    _draw_network(ax, entry)
    start, end = _xy(entry, checkpoints[0].positions), _xy(entry, checkpoints[-1].positions)
    ax.scatter(
        start[:, 0],
        start[:, 1],
        s=30,
        marker="o",
        facecolors="none",
        edgecolors="tab:blue",
        label="start",
    )
    ax.scatter(end[:, 0], end[:, 1], s=30, marker="x", color="tab:red", label="end")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title("reference positions")
    fig.tight_layout()
    paths.append(folder / "history_references.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths


def write_report(
    folder: Path,
    entry: NetworkEntry,
    *,
    fleet: dict[str, Any],
    summary: dict[str, Any],
    targets: Sequence[NetPosition],
    costs: npt.NDArray[np.float64],
    hours: npt.NDArray[np.int64],
    checkpoints: Sequence[Checkpoint],
    thresholds: Sequence[float] = DEFAULT_THRESHOLDS,
) -> dict[str, Any]:
    """Compute the report, write ``report.json`` and the plots; return the report."""
    folder.mkdir(parents=True, exist_ok=True)
    report = {
        "import": summary,
        "cost": fleet["cost"],
        "gap": gap_curve(
            entry,
            cost=str(fleet["cost"]),
            power=objective_power(fleet),
            targets=targets,
            checkpoints=checkpoints,
        ),
        "service_levels": service_levels(costs, hours, thresholds=thresholds),
        "references": {"start": checkpoints[0].positions, "end": checkpoints[-1].positions},
    }
    plots = plot_report(folder, entry, report, checkpoints)
    report["plots"] = [p.name for p in plots]
    (folder / "report.json").write_text(json_text(report, indent=2) + "\n")
    return report
