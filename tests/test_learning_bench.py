"""``bench/learning.py`` prints one JSON document on standard output (with ``--rest`` too:
the server it starts for the REST curve writes its banner elsewhere), and leaves out of
its medians an instance whose relative gaps would mean nothing."""

from __future__ import annotations

import itertools
import math
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import sumo

from routing_svc.demand import DemandDistribution
from routing_svc.optimum import candidate_sites
from routing_svc.types import NetPosition
from tests.helpers import bench_report

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # after every other module
from learning import instance, sample_cost, targets_batch_answer


def test_rest_curve_keeps_standard_output_json(tmp_path: Path) -> None:
    report, log = bench_report(
        "learning.py", tmp_path, "--nets", "grid", "--vehicles", "2", "--seeds", "0",
        "--rules", "consolidating", "--scenarios", "cold", "--targets", "300", "--jobs", "1",
        "--rest",
    )  # fmt: skip
    rest = report["rest"]
    assert rest["rule"] == "consolidating"
    assert set(rest["gaps"]) == {"300"}
    assert "API docs at" in log
    assert report["not_measured"] == []
    assert set(report["median_over_seeds"]) == {"grid/2"}


def test_instances_without_a_meaningful_gap_are_not_measured(tmp_path: Path) -> None:
    """SUMO's ``grid6`` has 8 car edges; three hotspots over them put 32 atoms, and 20
    vehicles stand within a fraction of a metre of each. SUMO's ``ingolstadt`` has 4 car
    edges and 16 candidate sites, fewer than 20 vehicles. Each record says why, no median
    counts it, and the network beside them is measured."""
    game = Path(sumo.SUMO_HOME) / "tools" / "game"
    grid6, ingolstadt = game / "grid6" / "grid6.net.xml", game / "fkk_in" / "ingolstadt.net.xml.gz"
    report, _ = bench_report(
        "learning.py", tmp_path, "--nets", f"grid6={grid6},ingolstadt={ingolstadt},grid",
        "--vehicles", "20", "--seeds", "0", "--rules", "consolidating,probe",
        "--scenarios", "cold", "--targets", "300", "--jobs", "1",
    )  # fmt: skip
    assert set(report["median_over_seeds"]) == {"grid/20"}
    why = {(x["network"], x["vehicles"], x["seed"]): x["why"] for x in report["not_measured"]}
    assert set(why) == {("grid6", 20, 0), ("ingolstadt", 20, 0)}
    assert "under 0.5% of one vehicle's" in why["grid6", 20, 0]
    assert "exceeds the 16 candidate sites" in why["ingolstadt", 20, 0]
    rules = {r["network"]: r["rules"] for r in report["records"]}
    assert rules["grid6"] == rules["ingolstadt"] == {}
    assert set(rules["grid"]) == {"consolidating", "probe"}


def test_the_batch_answer_is_the_p_median_of_the_targets_over_their_own_sites() -> None:
    """Two vehicles, 60 targets of ``grid``'s three hotspots: the batch answer serves the
    targets as well as the best of every pair of their candidate sites (the targets and
    the edge ends), found by brute force, and stands only on such sites. Both of its
    references stand on edge ends here, where no target came."""
    inst = instance("grid", 2, 0, shift=False)
    targets = inst.demand.sample(np.random.default_rng(21), 60)
    counts = Counter(targets)
    seen = list(counts)
    weights = np.array([counts[z] for z in seen], dtype=np.float64)
    sites = candidate_sites(
        inst.space.network, DemandDistribution.of_targets("seen", seen), max_sites=None
    )
    assert len(sites) <= 1500  # every site is offered: the brute force is exact
    costs = np.asarray(inst.space.cost_matrix(sites, seen))
    best = min(
        float(np.minimum(costs[i], costs[j]) @ weights)
        for i, j in itertools.combinations(range(len(sites)), 2)
    )
    answer = targets_batch_answer(inst.space, targets, 2)
    served = np.asarray(inst.space.cost_matrix(answer, seen)).min(axis=0) @ weights
    assert math.isclose(float(served), best, rel_tol=1e-9)
    assert set(answer) <= set(sites)
    assert not set(answer) & set(seen)


def test_sample_cost_is_the_mean_cost_from_the_closest_reference() -> None:
    """Hand-computed on one edge of ``grid``: a reference at its start and one at 30 m;
    targets at 10 m (10 m from the first), 30 m (0 m) and 40 m (10 m from the second)
    cost 20 / 3 m on average."""
    space = instance("grid", 2, 0, shift=False).space
    edge = next(e for e in range(space.network.n_edges) if space.network.length[e] > 50.0)
    references = [NetPosition(edge, 0.0), NetPosition(edge, 30.0)]
    targets = [NetPosition(edge, 10.0), NetPosition(edge, 30.0), NetPosition(edge, 40.0)]
    assert math.isclose(sample_cost(space, references, targets), 20.0 / 3.0, rel_tol=1e-12)


def test_the_fit_behind_the_batch_answer_is_paired_per_seed(tmp_path: Path) -> None:
    """Each cold record keeps the fleet's and the batch answer's cost on the targets seen at
    every checkpoint; the summary's median over seeds of their ratio less one is what the
    records give, and its worst from 1,000 targets on is reported beside the goals."""
    report, _ = bench_report(
        "learning.py", tmp_path, "--nets", "grid", "--vehicles", "2", "--seeds", "0,1,2",
        "--rules", "consolidating", "--scenarios", "cold", "--targets", "1000", "--jobs", "1",
    )  # fmt: skip
    records = report["records"]
    ratios = {
        label: sorted(
            r["rules"]["consolidating"]["cold"]["sample_costs"][label]
            / r["anchor"]["sample_costs"]["cold"][label]
            - 1.0
            for r in records
        )[1]
        for label in ("300", "1000")
    }
    entry = report["median_over_seeds"]["grid/2"]["consolidating"]["fit_behind_anchor_paired"]
    assert entry == ratios
    assert all(r["anchor"]["sample_costs"]["cold"]["1000"] > 0.0 for r in records)
    assert report["fit_behind_anchor_paired_from_1000"]["consolidating"] == {
        "worst": ratios["1000"],
        "where": "grid/2@1000",
    }
