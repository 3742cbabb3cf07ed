"""Coverage and routing in the plane against a peer and against the optimum.

Coverage (eq. (9), ``c = d**2``): the same stream of targets goes to our
fleet (``Fleet`` with the coverage objective and ``gamma_k = 1 / (k + 1)``
per vehicle: MacQueen's online k-means) and to scikit-learn's
``MiniBatchKMeans.partial_fit`` (the peer, in mini-batches of the stream),
both started at the first ``p`` targets. Offline k-means (Lloyd, best of 10
k-means++ starts on the evaluation sample) gives the reference.

Routing (eq. (10), ``c = d``): our fleet with the default routing schedule
against

- *continuous demand*: the best of several Cooper location-allocation runs
  on 8000 points of the evaluation sample (a near-exact continuous optimum);
- *discrete demand*: ``n`` points drawn uniformly in the square and weighted
  by the mixture density; the exact p-median over candidate sites = the
  points (MILP, HiGHS), and Cooper started from it (the continuous optimum
  can sit between demand points, so it can beat the discrete one). Our fleet
  sees targets drawn from the weighted points.

Every objective is evaluated on a held-out sample (continuous) or exactly
(discrete).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.cluster import KMeans, MiniBatchKMeans
from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

from routing_svc.paper.plane_demand import (
    Hotspot,
    Mixture,
    expected_cost,
    feed,
    plane_fleet,
)
from routing_svc.paper.plane_optimum import best_cooper, cooper, discrete_pmedian
from routing_svc.paper.result import ExperimentResult, quantile_band, seed_generators
from routing_svc.sa import COVERAGE, ROUTING, FleetConfig, InverseScaling, default_schedule
from routing_svc.types import FloatArray

SIDE = 10.0
DEMAND = Mixture(
    (
        Hotspot((2.5, 2.5), 0.9, 0.3),
        Hotspot((7.5, 3.0), 1.2, 0.25),
        Hotspot((4.0, 7.5), 0.7, 0.3),
        Hotspot((8.0, 8.0), 0.5, 0.15),
    )
)


def checkpoints(total: int) -> list[int]:
    """Roughly log-spaced numbers of targets, from 0 to ``total``."""
    marks = np.unique(np.geomspace(10, total, 24).astype(int))
    return [0, *(int(m) for m in marks if m < total), total]


def coverage_run(
    *, vehicles: int, targets: int, batch: int, rng: np.random.Generator
) -> dict[str, Any]:
    """One seed of the coverage comparison.

    scikit-learn runs single-threaded: its thread pool costs far more than it
    gains on batches of 100 points.
    """
    stream, _ = DEMAND.sample(rng, targets)
    evaluation, _ = DEMAND.sample(rng, 20_000)
    start = stream[:vehicles]
    marks = checkpoints(targets)
    fleet = plane_fleet(start, config=FleetConfig(COVERAGE, InverseScaling(1.0, 1.0)), side=SIDE)
    ours = [expected_cost(evaluation, s, power=2.0) for s in feed(fleet, stream, checkpoints=marks)]
    seed = int(rng.integers(2**31))
    peer = MiniBatchKMeans(n_clusters=vehicles, init=start, n_init=1, random_state=seed)
    peer_curve, seen = [expected_cost(evaluation, start, power=2.0)], 0
    with threadpool_limits(limits=1):
        for mark in marks[1:]:
            while seen < mark:
                chunk = stream[seen : max(min(seen + batch, mark), vehicles)]
                peer.partial_fit(chunk)
                seen += len(chunk)
            peer_curve.append(expected_cost(evaluation, peer.cluster_centers_, power=2.0))
        lloyd = KMeans(n_clusters=vehicles, n_init=10, random_state=seed).fit(evaluation)
    return {
        "marks": marks,
        "ours": ours,
        "peer": peer_curve,
        "lloyd": expected_cost(evaluation, lloyd.cluster_centers_, power=2.0),
        "final_sites": fleet_sites(fleet),
        "peer_sites": np.asarray(peer.cluster_centers_),
    }


def fleet_sites(fleet: Any) -> FloatArray:
    """The positions of a plane fleet as an array."""
    return np.asarray(fleet.state.positions, dtype=np.float64).reshape(-1, 2)


def routing_run(
    *, vehicles: int, targets: int, atoms: int, restarts: int, rng: np.random.Generator
) -> dict[str, Any]:
    """One seed of the routing comparison (continuous and discrete demand)."""
    schedule = default_schedule(typical_cost=SIDE, n_vehicles=vehicles, power=1.0)
    config = FleetConfig(ROUTING, schedule)
    stream, _ = DEMAND.sample(rng, targets)
    evaluation, _ = DEMAND.sample(rng, 20_000)
    fleet = plane_fleet(stream[:vehicles], config=config, side=SIDE)
    final = feed(fleet, stream, checkpoints=[targets])[-1]
    sample = evaluation[:8000]
    uniform = np.ones(len(sample))
    near_optimum = best_cooper(sample, uniform, count=vehicles, restarts=restarts, rng=rng)
    # discrete instance: uniform points weighted by the mixture density
    points = rng.uniform(0.0, SIDE, size=(atoms, 2))
    weights = _density(points)
    weights /= weights.sum()
    milp_sites, proven = discrete_pmedian(points, weights, count=vehicles)
    polished = cooper(points, weights, start=milp_sites)
    draws = points[rng.choice(atoms, size=targets, p=weights)]
    # start at the first distinct draws: two vehicles at one point tie, and the
    # one that loses every tie (by id) would never move
    _, first_seen = np.unique(draws, axis=0, return_index=True)
    start = draws[np.sort(first_seen)[:vehicles]]
    discrete_fleet = plane_fleet(start, config=config, side=SIDE)
    discrete_final = feed(discrete_fleet, draws, checkpoints=[targets])[-1]

    def discrete(sites: FloatArray) -> float:
        return expected_cost(points, sites, power=1.0, weights=weights)

    return {
        "continuous_ours": expected_cost(evaluation, final, power=1.0),
        "continuous_cooper": expected_cost(evaluation, near_optimum, power=1.0),
        "discrete_ours": discrete(discrete_final),
        "discrete_milp": discrete(milp_sites),
        "discrete_milp_proven": proven,
        "discrete_cooper_from_milp": discrete(polished),
        "sites": final,
        "cooper_sites": near_optimum,
        "discrete_points": points,
        "discrete_weights": weights,
        "discrete_sites": discrete_final,
        "milp_sites": milp_sites,
    }


def _density(points: FloatArray) -> FloatArray:
    total = np.zeros(len(points))
    for hotspot, share in zip(DEMAND.hotspots, DEMAND.probabilities(), strict=True):
        sq = ((points - np.asarray(hotspot.centre)) ** 2).sum(axis=1)
        total += share * np.exp(-sq / (2 * hotspot.spread**2)) / (2 * np.pi * hotspot.spread**2)
    return total


def run(*, seeds: int, quick: bool, seed: int = 0) -> ExperimentResult:
    """Coverage against MiniBatchKMeans and routing against the optimum, over seeds."""
    vehicles, batch = 6, 100
    targets = 3000 if quick else 20_000
    atoms, restarts = (40, 4) if quick else (80, 10)
    generators = seed_generators(seed, seeds)
    coverage = [
        coverage_run(vehicles=vehicles, targets=targets, batch=batch, rng=rng) for rng in generators
    ]
    routing = [
        routing_run(vehicles=vehicles, targets=targets, atoms=atoms, restarts=restarts, rng=rng)
        for rng in generators
    ]
    ours = np.array([c["ours"] for c in coverage])
    peer = np.array([c["peer"] for c in coverage])
    lloyd = np.array([c["lloyd"] for c in coverage])

    def median(key: str) -> float:
        return float(np.median([r[key] for r in routing]))

    def gap(values: FloatArray, reference: FloatArray) -> float:
        return float(np.median(values / reference - 1.0))

    def column(key: str) -> FloatArray:
        return np.array([r[key] for r in routing], dtype=np.float64)

    summary = {
        "vehicles": vehicles,
        "targets": targets,
        "coverage_ours_final_median": float(np.median(ours[:, -1])),
        "coverage_minibatch_final_median": float(np.median(peer[:, -1])),
        "coverage_lloyd_median": float(np.median(lloyd)),
        "coverage_ours_gap_to_lloyd_median": gap(ours[:, -1], lloyd),
        "coverage_minibatch_gap_to_lloyd_median": gap(peer[:, -1], lloyd),
        "routing_continuous_ours_median": median("continuous_ours"),
        "routing_continuous_cooper_median": median("continuous_cooper"),
        "routing_continuous_gap_median": gap(
            column("continuous_ours"), column("continuous_cooper")
        ),
        "routing_discrete_ours_median": median("discrete_ours"),
        "routing_discrete_milp_median": median("discrete_milp"),
        "routing_discrete_cooper_from_milp_median": median("discrete_cooper_from_milp"),
        "routing_discrete_gap_to_milp_median": gap(
            column("discrete_ours"), column("discrete_milp")
        ),
        "routing_discrete_gap_to_milp_worst": float(
            np.max(column("discrete_ours") / column("discrete_milp") - 1.0)
        ),
        "milp_proven_optimal_all": all(r["discrete_milp_proven"] for r in routing),
    }
    first = routing[0]
    return ExperimentResult(
        name="plane",
        title="Coverage vs MiniBatchKMeans, routing vs the p-median optimum (plane)",
        params={
            "seeds": seeds,
            "seed": seed,
            "vehicles": vehicles,
            "targets": targets,
            "minibatch_batch_size": batch,
            "discrete_points": atoms,
            "cooper_restarts": restarts,
            "hotspots": [
                {"centre": h.centre, "spread": h.spread, "weight": h.weight}
                for h in DEMAND.hotspots
            ],
        },
        summary=summary,
        series={
            "marks": coverage[0]["marks"],
            "coverage_ours": quantile_band(ours),
            "coverage_minibatch": quantile_band(peer),
            "coverage_lloyd_median": float(np.median(lloyd)),
            "coverage_sites_seed0": coverage[0]["final_sites"],
            "coverage_peer_sites_seed0": coverage[0]["peer_sites"],
            "routing_sites_seed0": first["sites"],
            "routing_cooper_sites_seed0": first["cooper_sites"],
            "discrete_points_seed0": first["discrete_points"],
            "discrete_weights_seed0": first["discrete_weights"],
            "discrete_sites_seed0": first["discrete_sites"],
            "milp_sites_seed0": first["milp_sites"],
            "routing_table": {
                key: column(key)
                for key in (
                    "continuous_ours",
                    "continuous_cooper",
                    "discrete_ours",
                    "discrete_milp",
                    "discrete_cooper_from_milp",
                )
            },
        },
    )
