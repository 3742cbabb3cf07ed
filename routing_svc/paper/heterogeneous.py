"""Heterogeneous routing: vehicles of types A and B (section IV-C, Fig. 2).

Targets of type ``a`` need one A vehicle, ``b`` one B, ``ab`` one A and one
B; a target is served when the last required vehicle arrives, and only that
vehicle moves (``Fleet.observe`` with ``requires``). The demand is the
paper's: ``a`` with probability 0.4 around (2, 6), ``b`` 0.2 around (6, 2),
``ab`` 0.4 around (6, 6) (isotropic Gaussians of standard deviation
``spread``, our choice). The objective, eq. (11), is the expected completion
time

``J(p) = E[ max_{t in requires(z)} min_{i of type t} |p_i - z| / v_i ]``,

evaluated here on a held-out sample. The paper's claim: A and B vehicles
pair up near (6, 6), where both are needed together.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from routing_svc.paper.plane_demand import Hotspot, Mixture, distances, feed, plane_fleet
from routing_svc.paper.result import ExperimentResult, quantile_band, seed_generators
from routing_svc.sa import ROUTING, FleetConfig, default_schedule
from routing_svc.types import FloatArray

SIDE = 8.0
PAIR_CENTRE = (6.0, 6.0)


def demand(spread: float) -> Mixture:
    """The paper's three target types."""
    return Mixture(
        (
            Hotspot((2.0, 6.0), spread, 0.4, ("A",)),
            Hotspot((6.0, 2.0), spread, 0.2, ("B",)),
            Hotspot(PAIR_CENTRE, spread, 0.4, ("A", "B")),
        )
    )


def completion_time(
    points: FloatArray, kinds: FloatArray, mixture: Mixture, sites: FloatArray, types: list[str]
) -> float:
    """The objective (11) on a sample: mean over targets of the last arrival time."""
    d = distances(points, sites)
    labels = np.asarray(types)
    nearest = {t: d[:, labels == t].min(axis=1) for t in sorted(set(types))}
    times = np.zeros(len(points))
    for index, hotspot in enumerate(mixture.hotspots):
        rows = kinds == index
        for t in hotspot.requires:
            times[rows] = np.maximum(times[rows], nearest[t][rows])
    return float(times.mean())


def pairs_near(
    sites: FloatArray, types: list[str], *, centre: tuple[float, float], radius: float, gap: float
) -> list[tuple[int, int, float]]:
    """Mutually nearest (A, B) vehicles within ``gap`` of each other and ``radius`` of ``centre``.

    Returns ``(a_index, b_index, separation)`` for each pair.
    """
    labels = np.asarray(types)
    a_rows, b_rows = np.flatnonzero(labels == "A"), np.flatnonzero(labels == "B")
    d = distances(sites[a_rows], sites[b_rows])
    found = []
    for i, a in enumerate(a_rows):
        j = int(d[i].argmin())
        if int(d[:, j].argmin()) != i or d[i, j] > gap:
            continue
        middle = (sites[a] + sites[b_rows[j]]) / 2.0
        if np.hypot(*(middle - np.asarray(centre))) <= radius:
            found.append((int(a), int(b_rows[j]), float(d[i, j])))
    return found


def one_run(
    *, per_type: int, targets: int, spread: float, rng: np.random.Generator
) -> dict[str, Any]:
    """One seeded run from random starting positions in the square."""
    mixture = demand(spread)
    types = ["A"] * per_type + ["B"] * per_type
    start = rng.uniform(0.0, SIDE, size=(len(types), 2))
    schedule = default_schedule(typical_cost=SIDE, n_vehicles=len(types), power=1.0)
    fleet = plane_fleet(start, config=FleetConfig(ROUTING, schedule), side=SIDE, types=types)
    stream, kinds = mixture.sample(rng, targets)
    requires = [mixture.hotspots[int(k)].requires for k in kinds]
    marks = [0, *np.unique(np.geomspace(10, targets, 20).astype(int)).tolist()]
    snapshots = feed(fleet, stream, checkpoints=marks, requires=requires)
    evaluation, evaluation_kinds = mixture.sample(rng, 10_000)
    curve = [completion_time(evaluation, evaluation_kinds, mixture, s, types) for s in snapshots]
    pairs = pairs_near(snapshots[-1], types, centre=PAIR_CENTRE, radius=1.0, gap=0.5)
    return {
        "marks": marks,
        "curve": curve,
        "start": start,
        "final": snapshots[-1],
        "types": types,
        "pairs": pairs,
    }


def run(*, seeds: int, quick: bool, seed: int = 0) -> ExperimentResult:
    """Run the heterogeneous fleet over ``seeds`` seeds."""
    per_type, spread = 3, 0.6
    targets = 4000 if quick else 20_000
    runs = [
        one_run(per_type=per_type, targets=targets, spread=spread, rng=rng)
        for rng in seed_generators(seed, seeds)
    ]
    curves = np.array([r["curve"] for r in runs])
    pair_counts = np.array([len(r["pairs"]) for r in runs])
    separations = [p[2] for r in runs for p in r["pairs"]]
    first = runs[0]
    return ExperimentResult(
        name="heterogeneous",
        title="Heterogeneous routing (Fig. 2): A and B vehicles pair up near (6, 6)",
        params={
            "seeds": seeds,
            "seed": seed,
            "vehicles_per_type": per_type,
            "targets": targets,
            "spread": spread,
            "demand": [
                {"type": "".join(h.requires).lower(), "centre": h.centre, "probability": h.weight}
                for h in demand(spread).hotspots
            ],
            "pair_rule": "mutually nearest A-B within 0.5, midpoint within 1.0 of (6, 6)",
        },
        summary={
            "objective_start_median": float(np.median(curves[:, 0])),
            "objective_final_median": float(np.median(curves[:, -1])),
            "seeds_with_a_pair_near_6_6": int(np.sum(pair_counts > 0)),
            "pairs_near_6_6_median": float(np.median(pair_counts)),
            "pair_separation_median": float(np.median(separations)) if separations else None,
        },
        series={
            "marks": first["marks"],
            "objective": quantile_band(curves),
            "start_seed0": first["start"],
            "final_seed0": first["final"],
            "types": first["types"],
            "pairs_seed0": first["pairs"],
        },
    )
