"""PNG plots of a co-simulation (matplotlib, Agg; no display needed).

- :func:`plot_waits`: SUMO's measured wait over the run, per policy (mean over
  10-minute bins of request time, averaged over seeds);
- :func:`plot_positions`: the network with the demand, the SA's reference
  positions at the start and at the end, and the optimum;
- :func:`plot_objective`: the SA objective (exact expected free-flow wait of
  the reference positions) over time, with the optimum as a line;
- :func:`write_figures`: all three for one experiment.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.network import RoadSpace
from routing_svc.sim.experiment import CosimResult
from routing_svc.sim.scenario import empirical_demand
from routing_svc.types import NetPosition

__all__ = ["plot_objective", "plot_positions", "plot_waits", "write_figures"]

_COLOURS = {
    "sa": "tab:blue",
    "sa-available": "tab:olive",
    "sa-floor": "tab:cyan",
    "sa-cold": "tab:purple",
    "static": "tab:gray",
    "optimum": "tab:green",
    "sumo-stop": "tab:red",
    "sumo-closest": "tab:pink",
    "sumo-circling": "tab:orange",
    "sumo-taxistand": "tab:brown",
}
BIN_SECONDS = 600.0


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_waits(result: CosimResult, path: Path, *, title: str) -> Path:
    """Mean SUMO wait per 10-minute bin of request time, one line per policy."""
    plt = _pyplot()
    start = result.spec.warmup
    edges = np.arange(start, start + result.spec.duration + BIN_SECONDS, BIN_SECONDS)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for name, runs in result.by_policy().items():
        per_seed = []
        for run in runs:
            served = [(t, w) for t, w, ok in run.waits if ok and t >= start]
            times = np.array([t for t, _ in served])
            waits = np.array([w for _, w in served])
            which = np.digitize(times, edges) - 1
            per_seed.append(
                [
                    waits[which == b].mean() if np.any(which == b) else np.nan
                    for b in range(len(edges) - 1)
                ]
            )
        mean = np.nanmean(np.array(per_seed, dtype=float), axis=0)
        centres = (edges[:-1] + BIN_SECONDS / 2 - start) / 60.0
        ax.plot(centres, mean, marker="o", ms=3, label=name, color=_COLOURS.get(name))
    ax.set_xlabel("request time (min after the first request)")
    ax.set_ylabel("mean wait from SUMO (s)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _draw_network(
    ax: Any, space: RoadSpace, demand: DemandDistribution[NetPosition] | None
) -> None:
    from matplotlib.collections import LineCollection

    net = space.network
    lines = [
        net.shape_xy[net.shape_offsets[i] : net.shape_offsets[i + 1]] for i in range(net.n_edges)
    ]
    widths = np.full(net.n_edges, 0.4)
    colours: Any = "0.75"
    if demand is not None:
        mass = np.zeros(net.n_edges)
        for position, weight in zip(demand.positions, demand.weights, strict=True):
            mass[position.edge] += weight
        density = mass / net.length
        scale = density / density.max() if density.max() > 0 else density
        widths = 0.4 + 3.0 * scale
        colours = [(0.75 - 0.55 * s, 0.75 - 0.35 * s, 0.75 + 0.2 * s) for s in scale]
    ax.add_collection(LineCollection(lines, linewidths=widths, colors=colours, zorder=1))
    ax.autoscale()
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def plot_positions(
    result: CosimResult,
    space: RoadSpace,
    demand: DemandDistribution[NetPosition] | None,
    path: Path,
    *,
    title: str,
    policy: str = "sa",
) -> Path:
    """The network (demand drawn as edge width), SA positions at start and end, optimum."""
    plt = _pyplot()
    xmin, ymin, xmax, ymax = space.network.bounds
    height = 8.0 * (ymax - ymin) / max(xmax - xmin, 1.0) + 0.8
    fig, ax = plt.subplots(figsize=(8.0, min(max(height, 4.0), 9.0)))
    _draw_network(ax, space, demand)
    runs = sorted(result.by_policy().get(policy, []), key=lambda r: r.seed)
    index = space.network.edge_index

    def xy(positions: Sequence[tuple[str, float]]) -> np.ndarray:
        return np.array([space.xy(NetPosition(index[e], float(o))) for e, o in positions])

    if runs:
        run = runs[0]
        start = result.start.get(run.seed) or list(run.snapshots[0][1].values())
        first = xy(start)
        last = xy(list(run.snapshots[-1][1].values()))
        for a, b in zip(first, last, strict=True):
            ax.annotate("", xy=b, xytext=a, arrowprops={"arrowstyle": "->", "color": "0.4"})
        ax.scatter(
            *first.T,
            s=40,
            facecolors="none",
            edgecolors="k",
            label="start (before any learning)",
            zorder=3,
        )
        ax.scatter(*last.T, s=40, color="tab:blue", label=f"{policy} end", zorder=4)
        optimum = result.optimum.get(run.seed)
        if optimum is not None:
            opt = np.array([space.xy(p) for p in optimum.positions])
            ax.scatter(*opt.T, s=90, marker="*", color="tab:green", label="optimum", zorder=5)
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_objective(
    result: CosimResult,
    path: Path,
    *,
    title: str,
    policies: Sequence[str] = ("sa", "sa-cold", "sa-floor", "static"),
    shift_at: float | None = None,
) -> Path:
    """Exact expected free-flow wait of the reference positions over time, with the optimum."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    start = result.spec.warmup
    for name in policies:
        curves = [c for (p, _), c in sorted(result.curves.items()) if p == name]
        if not curves:
            continue
        n = min(len(c) for c in curves)
        times = (np.array([t for t, _ in curves[0][:n]]) - start) / 60.0
        values = np.mean([[v for _, v in c[:n]] for c in curves], axis=0)
        ax.plot(times, values, label=name, color=_COLOURS.get(name), drawstyle="steps-post")
    if result.optimum_curve:
        curves = list(result.optimum_curve.values())
        n = min(len(c) for c in curves)
        times = (np.array([t for t, _ in curves[0][:n]]) - start) / 60.0
        values = np.mean([[v for _, v in c[:n]] for c in curves], axis=0)
        ax.plot(
            times,
            values,
            "--",
            color="tab:green",
            label="optimum (p-median)",
            drawstyle="steps-post",
        )
    if shift_at is not None:
        ax.axvline(shift_at / 60.0, color="k", lw=0.8, ls=":", label="hotspots move")
    ax.set_xlabel("time (min after the first request)")
    ax.set_ylabel("expected free-flow wait (s)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


FIGURE_KINDS = ("waits", "positions", "objective")
"""The figures :func:`write_figures` draws, in the order a report shows them."""


def figure_path(out_dir: Path, prefix: str, kind: str) -> Path:
    """Where :func:`write_figures` puts the figure ``kind`` of ``prefix``."""
    return out_dir / f"{prefix}-{kind}.png"


def write_figures(result: CosimResult, *, out_dir: Path, prefix: str) -> dict[str, Path]:
    """Waits over the run, positions on the network, SA objective over time.

    Returns
    -------
    dict
        ``"waits"``, ``"positions"`` and ``"objective"`` -> the PNG written
        (``positions`` and ``objective`` only when a service policy ran).
    """
    prepared = result.prepared
    if prepared is None:
        raise ValueError("the result has no prepared inputs to draw")
    spec = result.spec
    out_dir.mkdir(parents=True, exist_ok=True)
    label = f"{Path(spec.network).name.split('.')[0]}, {spec.mode}, {spec.vehicles} vehicles"
    paths = {
        "waits": plot_waits(
            result,
            figure_path(out_dir, prefix, "waits"),
            title=f"SUMO-measured wait ({label})",
        )
    }
    if not result.curves:
        return paths
    if prepared.phases is not None:
        demand = prepared.phases[0].demand
    else:
        demand = empirical_demand(prepared.network, prepared.seeds[0].requests)
    learners = [p.name for p in spec.policies if p.learn]
    policy = learners[0] if learners else spec.policies[0].name
    paths["positions"] = plot_positions(
        result,
        prepared.space,
        demand,
        figure_path(out_dir, prefix, "positions"),
        title=f"{policy}: start (o) -> end of the run (filled), optimum (star); {label}",
        policy=policy,
    )
    paths["objective"] = plot_objective(
        result,
        figure_path(out_dir, prefix, "objective"),
        title=f"SA objective vs optimum ({label})",
        shift_at=spec.shift_at,
    )
    return paths
