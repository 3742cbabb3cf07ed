"""Figures of the paper experiments, drawn from their JSON records alone.

Each ``draw_*`` function takes an :class:`ExperimentResult` (or the dict
read back from its JSON) and returns a matplotlib ``Figure``; nothing here
computes an experiment, so a figure can be redrawn from a stored JSON file.
:func:`save_figure` is the one function that writes a file.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from routing_svc.paper.result import ExperimentResult

COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"]


def _band(ax: Axes, x: Any, band: dict[str, Any], *, label: str, colour: str) -> None:
    ax.plot(x, band["median"], color=colour, label=label)
    low = np.asarray(band["q10"], dtype=float)
    high = np.asarray(band["q90"], dtype=float)
    ax.fill_between(np.asarray(x, dtype=float), low, high, color=colour, alpha=0.2, lw=0)


def draw_source_seeking(result: ExperimentResult) -> Figure:
    """Distance to the source against periods and against measurements."""
    series, summary = result.series, result.summary
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    period = np.asarray(series["period"], dtype=float)
    labels = {
        "formation": "triangle formation, rigid (3 meas./period)",
        "shrinking": "triangle formation, radius c_k (3)",
        "spsa": "single robot, SPSA (2)",
        "kw": "single robot, Kiefer-Wolfowitz (4)",
    }
    for colour, (name, label) in zip(COLOURS, labels.items(), strict=False):
        per = summary[name]["measurements_per_period"]
        _band(left, period, series[name], label=label, colour=colour)
        right.plot(period * per, series[name]["median"], color=colour, label=label)
    for ax, xlabel in ((left, "period k"), (right, "measurements used")):
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.axhline(summary["found_radius"], color="grey", ls=":", lw=1)
        ax.grid(alpha=0.3)
    left.set_ylabel("distance of the centre to the source")
    left.set_title(f"median and 10-90 % band over {result.params['seeds']} seeds")
    right.set_title("median against the number of measurements")
    right.legend(fontsize=8)
    fig.tight_layout()
    return fig


def draw_fading(result: ExperimentResult) -> Figure:
    """Snapshots of the chain over the shadowing map (Fig. 1) and the minimum link SNR."""
    series, params = result.series, result.params
    snapshots = np.asarray(series["snapshots"], dtype=float)
    periods = series["snapshot_periods"]
    fig, axes = plt.subplots(
        1, 3, figsize=(14, 4.4), layout="constrained", gridspec_kw={"width_ratios": [1, 1, 0.9]}
    )
    base, target = params["base"], params["target"]
    shadow = np.asarray(series["shadowing_seed0"], dtype=float)
    image = None
    for ax, picks in zip(axes[:2], ((0, 1), (2, 3)), strict=True):
        image = ax.imshow(
            shadow, origin="lower", extent=series["extent"], cmap="RdYlGn", vmin=-25, vmax=6
        )
        shown = [index for index in picks if index < len(periods)]
        for colour, index in zip(("black", "blue"), shown, strict=False):
            chain = np.vstack([base, snapshots[index], target])
            ax.plot(
                chain[:, 0], chain[:, 1], "o-", color=colour, ms=4, label=f"k = {periods[index]}"
            )
        ax.plot(*base, "ks", ms=9)
        ax.plot(*target, "k*", ms=13)
        ax.annotate("base", base, xytext=(4, 6), textcoords="offset points")
        ax.annotate("target", target, xytext=(-34, 8), textcoords="offset points")
        ax.set_title("chain, k = " + ", ".join(str(periods[i]) for i in shown) + " (map of seed 0)")
        ax.legend(loc="upper left", fontsize=8)
    if image is not None:
        fig.colorbar(image, ax=axes[:2], shrink=0.85, label="shadowing S (dB)")
    ax = axes[2]
    _band(
        ax,
        series["period"],
        series["min_link_snr"],
        label=f"worst link, median/10-90 % over {params['seeds']} maps",
        colour=COLOURS[0],
    )
    ax.axhline(params["threshold_db"], color="red", ls="--", label="threshold")
    ax.set_xlabel("period k")
    ax.set_ylabel("local-mean SNR (dB)")
    ax.set_title("minimum link SNR")
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    return fig


def draw_plane(result: ExperimentResult) -> Figure:
    """Coverage curves against MiniBatchKMeans; routing sites against the optimum."""
    series, summary = result.series, result.summary
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6), layout="constrained")
    marks = np.maximum(np.asarray(series["marks"], dtype=float), 1.0)
    left = axes[0]
    _band(left, marks, series["coverage_ours"], label="ours: Fleet, c = d^2", colour=COLOURS[0])
    _band(left, marks, series["coverage_minibatch"], label="MiniBatchKMeans", colour=COLOURS[1])
    left.axhline(
        series["coverage_lloyd_median"],
        color="black",
        ls="--",
        label="offline k-means (best of 10)",
    )
    left.set_xscale("log")
    left.set_yscale("log")
    left.set_xlabel("targets seen")
    left.set_ylabel("coverage cost E[min |p - z|^2]")
    left.set_title(f"coverage, same stream ({result.params['seeds']} seeds)")
    left.legend(fontsize=8)
    left.grid(alpha=0.3)
    middle = axes[1]
    sites = np.asarray(series["routing_sites_seed0"], dtype=float)
    cooper = np.asarray(series["routing_cooper_sites_seed0"], dtype=float)
    cover = np.asarray(series["coverage_sites_seed0"], dtype=float)
    peer = np.asarray(series["coverage_peer_sites_seed0"], dtype=float)
    for hotspot in result.params["hotspots"]:
        middle.add_patch(Circle(hotspot["centre"], 2 * hotspot["spread"], color="grey", alpha=0.15))
    middle.plot(*cover.T, "o", mfc="none", color=COLOURS[0], ms=10, label="coverage: ours")
    middle.plot(*peer.T, "+", color=COLOURS[1], ms=10, label="coverage: MiniBatchKMeans")
    middle.plot(*sites.T, "s", color=COLOURS[2], label="routing: ours")
    middle.plot(*cooper.T, "x", color="black", ms=9, label="routing: Cooper (near-optimal)")
    middle.set_xlim(0, 10)
    middle.set_ylim(0, 10)
    middle.set_aspect("equal")
    middle.set_title("final positions, continuous demand (seed 0)")
    middle.legend(fontsize=7, loc="lower right")
    right = axes[2]
    points = np.asarray(series["discrete_points_seed0"], dtype=float)
    weights = np.asarray(series["discrete_weights_seed0"], dtype=float)
    right.scatter(*points.T, s=4 + 600 * weights, color="grey", alpha=0.5, label="demand points")
    milp = np.asarray(series["milp_sites_seed0"], dtype=float)
    ours = np.asarray(series["discrete_sites_seed0"], dtype=float)
    right.plot(*milp.T, "x", color="black", ms=9, label="exact p-median (MILP)")
    right.plot(*ours.T, "s", mfc="none", color=COLOURS[2], ms=9, label="routing: ours")
    right.set_xlim(0, 10)
    right.set_ylim(0, 10)
    right.set_aspect("equal")
    gap = 100 * summary["routing_discrete_gap_to_milp_median"]
    right.set_title(f"discrete demand (seed 0); median gap {gap:.1f} %")
    right.legend(fontsize=7, loc="lower right")
    return fig


def draw_heterogeneous(result: ExperimentResult) -> Figure:
    """Fig. 2: final A/B positions and the objective (11) over time."""
    series, params = result.series, result.params
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.8), layout="constrained")
    for item in params["demand"]:
        left.add_patch(Circle(item["centre"], 2 * params["spread"], color="grey", alpha=0.15))
        left.annotate(
            f"{item['type']} ({100 * item['probability']:.0f} %)",
            item["centre"],
            xytext=(0, 40),
            textcoords="offset points",
            ha="center",
        )
    types = np.asarray(series["types"])
    start = np.asarray(series["start_seed0"], dtype=float)
    final = np.asarray(series["final_seed0"], dtype=float)
    for name, marker, colour in (("A", "o", COLOURS[0]), ("B", "^", COLOURS[1])):
        rows = types == name
        left.plot(
            *start[rows].T, marker, mfc="none", color=colour, alpha=0.5, label=f"{name} start"
        )
        left.plot(*final[rows].T, marker, color=colour, ms=9, label=f"{name} final")
        for a, b in zip(start[rows], final[rows], strict=True):
            left.annotate("", b, a, arrowprops={"arrowstyle": "->", "color": colour, "alpha": 0.4})
    left.set_xlim(0, 8)
    left.set_ylim(0, 8)
    left.set_aspect("equal")
    left.set_title("vehicles, seed 0 (pairs: " + str(len(series["pairs_seed0"])) + ")")
    left.legend(fontsize=8, loc="lower left")
    marks = np.maximum(np.asarray(series["marks"], dtype=float), 1.0)
    _band(
        right, marks, series["objective"], label="E[completion time], eq. (11)", colour=COLOURS[2]
    )
    right.set_xscale("log")
    right.set_xlabel("targets seen")
    right.set_ylabel("expected completion time")
    right.set_title(f"objective (11), median and 10-90 % over {params['seeds']} seeds")
    right.legend(fontsize=8)
    right.grid(alpha=0.3)
    return fig


def draw_tracking(result: ExperimentResult) -> Figure:
    """Tracking error of the SPSA robot and lag of the fleet for each step rule."""
    series = result.series
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    labels = {
        "decreasing": "decreasing a_k",
        "floor": "decreasing to a floor",
        "constant": "constant",
    }
    styles = {"decreasing": "-", "floor": "-", "constant": "--"}
    for colour, (rule, label) in zip(COLOURS, labels.items(), strict=False):
        _band(left, series["period"], series["source"][rule], label=label, colour=colour)
        right.plot(
            series["marks"],
            series["fleet"][rule]["median"],
            styles[rule],
            color=colour,
            label=label,
        )
    left.set_title("SPSA robot, source on a circle (1 turn)")
    left.set_xlabel("period k")
    left.set_ylabel("distance to the moving source")
    right.set_title(f"fleet, hotspot on a circle ({result.params['fleet_turns']:g} turns)")
    right.set_xlabel("targets seen")
    right.set_ylabel("hotspot centre to nearest vehicle (median)")
    for ax in (left, right):
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    return fig


DRAWERS: dict[str, Callable[[ExperimentResult], Figure]] = {
    "source-seeking": draw_source_seeking,
    "fading": draw_fading,
    "plane": draw_plane,
    "heterogeneous": draw_heterogeneous,
    "tracking": draw_tracking,
}


def draw(result: ExperimentResult) -> Figure:
    """The figure of any experiment."""
    return DRAWERS[result.name](result)


def save_figure(figure: Figure, path: Path) -> None:
    """Write ``figure`` as a PNG and release it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(figure)
