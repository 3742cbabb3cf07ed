"""Seconds of one consolidation, compiled kernels against the numpy form they replaced.

For each network and fleet size: a three-hotspot demand
(:func:`routing_svc.demand.network.hotspot_mixture`), a reservoir of its targets
and two consolidations (:func:`routing_svc.sa.consolidation.consolidate`, four
folds, the default policy's):

- ``cold``: from random references (the test pays: the whole reservoir is solved
  too);
- ``warm``: from the references the cold one chose, on a fresh reservoir.

Each is timed with the package's kernels (lazy greedy addition, the compiled
fast interchange) and with ``numpy``, the vectorised greedy addition and fast
interchange the package used before (the named baseline, the reference of
``tests/sa/test_interchange.py``), in the same run, best of ``--repeat``.
Reported: seconds of each (and the part spent on the cost matrix, common to
both), the ratio ``numpy / kernels`` and whether both chose the same
configuration (same decision, references and step counters).

Run: ``python bench/consolidation.py`` or, e.g.,
``python bench/consolidation.py --nets drt --vehicles 20 --repeat 1``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np
from bench_shared import SHARED

import routing_svc.sa.consolidation as consolidation
from routing_svc.demand.network import hotspot_mixture
from routing_svc.network import RoadSpace, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.sa.consolidation import Consolidation, ConsolidationPolicy, consolidate
from routing_svc.types import FloatArray, NetPosition

REPO = Path(__file__).resolve().parents[1]
NETWORKS = {"drt": "drt", "badhersfeld": str(SHARED / "badhersfeld.net.xml.gz")}


class TimedSpace:
    """A road space that adds up the seconds spent in :meth:`cost_matrix`."""

    def __init__(self, space: RoadSpace) -> None:
        self.space = space
        self.seconds = 0.0

    def candidate_references(
        self, sample: Sequence[NetPosition], fixed: Sequence[NetPosition]
    ) -> list[NetPosition]:
        return self.space.candidate_references(sample, fixed)

    def cost_matrix(self, sources: list[NetPosition], targets: list[NetPosition]) -> FloatArray:
        t0 = time.perf_counter()
        out = self.space.cost_matrix(sources, targets)
        self.seconds += time.perf_counter() - t0
        return out


def numpy_baseline() -> Any:
    """A context in which consolidations solve with the numpy greedy addition and fast
    interchange."""
    if str(REPO) not in sys.path:  # the baseline is the reference of the tests
        sys.path.insert(0, str(REPO))
    from tests.sa.test_interchange import reference_fast_interchange, reference_greedy

    def fast_interchange(
        c: FloatArray, w: FloatArray, sites: Any, *, transposed: FloatArray | None = None
    ) -> Any:
        """The numpy form, which has no use for the transposed costs."""
        return reference_fast_interchange(c, w, sites)

    return mock.patch.multiple(
        consolidation, greedy=reference_greedy, fast_interchange=fast_interchange
    )


def timed(
    run: Callable[[], Consolidation[NetPosition]], space: TimedSpace, repeat: int
) -> tuple[float, float, Consolidation[NetPosition]]:
    """Best seconds of ``repeat`` runs, the cost-matrix seconds of that run, its result."""
    best = (np.inf, 0.0)
    for _ in range(repeat):
        space.seconds = 0.0
        t0 = time.perf_counter()
        result = run()
        seconds = time.perf_counter() - t0
        best = min(best, (seconds, space.seconds))
    return best[0], best[1], result


def case(
    space: TimedSpace,
    positions: list[NetPosition],
    reservoir: list[NetPosition],
    repeat: int,
) -> tuple[dict[str, Any], Consolidation[NetPosition]]:
    policy = ConsolidationPolicy()

    def run() -> Consolidation[NetPosition]:
        return consolidate(
            space,
            positions,
            positions,
            reservoir,
            power=1.0,
            speed=1.0,
            confidence=policy.confidence,
            updates=[1] * len(positions),
            fresh=len(reservoir),
            folds=policy.folds,
        )

    fast, fast_matrix, chosen = timed(run, space, repeat)
    with numpy_baseline():
        slow, slow_matrix, baseline = timed(run, space, repeat)
    return {
        "kernels_seconds": round(fast, 3),
        "numpy_seconds": round(slow, 3),
        "ratio": round(slow / fast, 2),
        "cost_matrix_seconds": round(min(fast_matrix, slow_matrix), 3),
        "solve_ratio": round((slow - slow_matrix) / (fast - fast_matrix), 2),
        "accepted": chosen.accepted,
        "same_configuration": chosen == baseline,
        # the reservoir's mean cost afterwards, by each (equal when the configurations are)
        "kernels_sample_after": chosen.sample_after,
        "numpy_sample_after": baseline.sample_after,
    }, chosen


def bench_network(net: str, fleets: list[int], reservoir: int, repeat: int) -> dict[str, Any]:
    network = load_network(resolve_network(NETWORKS[net]))
    space = TimedSpace(RoadSpace(network))
    demand = hotspot_mixture(network, centres=3, rng=np.random.default_rng([0, 0]))
    out: dict[str, Any] = {"edges": network.n_edges}
    for n in fleets:
        rng = np.random.default_rng([n, 1])
        edges = rng.choice(network.n_edges, size=n, replace=False)
        start = [NetPosition(int(e), 0.0) for e in edges]
        cold, chosen = case(space, start, demand.sample(rng, reservoir), repeat)
        warm, _ = case(space, list(chosen.positions), demand.sample(rng, reservoir), repeat)
        out[f"{n}_vehicles"] = {"cold": cold, "warm": warm}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--nets", default=",".join(NETWORKS))
    parser.add_argument("--vehicles", default="20,50")
    parser.add_argument("--reservoir", type=int, default=ConsolidationPolicy().reservoir)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    try:
        fleets = [int(v) for v in args.vehicles.split(",")]
    except ValueError:
        parser.error(f"--vehicles takes comma-separated integers, got {args.vehicles!r}")
    if args.repeat < 1 or args.reservoir < 2 or min(fleets) < 1:
        parser.error("--repeat and every fleet size must be >= 1, --reservoir >= 2")
    # compile the kernels outside the timing
    warmup = TimedSpace(RoadSpace(load_network(resolve_network("drt"))))
    positions = [NetPosition(e, 0.0) for e in range(3)]
    case(warmup, positions, [NetPosition(e, 0.0) for e in range(3, 40)], 1)
    report: dict[str, Any] = {
        "baseline": "numpy greedy addition and fast interchange",
        "reservoir": args.reservoir,
        "repeat": args.repeat,
        "networks": {},
    }
    for net in args.nets.split(","):
        if net not in NETWORKS:
            parser.error(f"unknown network {net!r}; known: {', '.join(NETWORKS)}")
        if net != "drt" and not Path(NETWORKS[net]).exists():
            report["networks"][net] = {"skipped": f"{NETWORKS[net]} is absent"}
            continue
        report["networks"][net] = bench_network(net, fleets, args.reservoir, args.repeat)
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
