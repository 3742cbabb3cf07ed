"""``bench/heterogeneous.py`` prints one JSON document whose summary is that of its
records, prices the per-type optima at the optimum by objective (11), gives the same curve
through the REST API, and refuses bad options before any work."""

from __future__ import annotations

import math
import statistics
from pathlib import Path

from tests.helpers import assert_bench_refuses, bench_report

RULES = ("probe", "paper", "consolidating", "per_type")


def test_heterogeneous_report_is_its_records(tmp_path: Path) -> None:
    report, _ = bench_report(
        "heterogeneous.py", tmp_path, "--nets", "grid", "--vehicles", "4", "--seeds", "0,1",
        "--targets", "1000", "--jobs", "1",
    )  # fmt: skip
    records = report["records"]
    assert [(r["network"], r["vehicles"], r["seed"]) for r in records] == [
        ("grid", 4, 0),
        ("grid", 4, 1),
    ]
    labels = ["300", "1000"]
    table = report["median_over_seeds"]["grid/4"]
    for r in records:
        assert abs(r["gap_at_optimum"]) < 1e-9  # the decomposition is objective (11)
        assert list(r["batch"]) == labels
        for rule in RULES:
            for scenario in ("cold", "warm"):
                gaps = r[rule][scenario]
                assert list(gaps) == labels
                assert all(math.isfinite(g) and g > -0.5 for g in gaps.values())
    for label in labels:
        assert table["batch"][label] == statistics.median(r["batch"][label] for r in records)
        for rule in RULES:
            assert table[rule]["cold"][label] == statistics.median(
                r[rule]["cold"][label] for r in records
            )
    same = sum(r["consolidating"] == r["per_type"] for r in records)
    assert report["same_as_per_type"] == same
    for rule in RULES:
        worst_warm = max(table[rule]["warm"].values())
        assert report["goals"][rule]["warm_every"] == [worst_warm, "grid/4", worst_warm <= 0.05]
        assert report["goals"][rule]["cold_3000"] is None  # no checkpoint at 3,000 here


def test_heterogeneous_refuses_bad_options_before_any_work(tmp_path: Path) -> None:
    assert_bench_refuses(
        "heterogeneous.py",
        tmp_path,
        [
            (["--nets", "nosuch"], "'nosuch' is neither a known network"),
            (["--targets", "10"], "--targets must be at least 300 and --jobs at least 1"),
            (["--vehicles", "1"], "--vehicles: at least 2 (one of each type)"),
            (["--mix", "halves"], "invalid choice: 'halves'"),
            (["--demand", "nosuch"], "--demand must be 'uniform'"),
        ],
    )


def test_a_third_of_the_targets_need_both_types(tmp_path: Path) -> None:
    report, log = bench_report(
        "heterogeneous.py", tmp_path, "--nets", "drt", "--vehicles", "4", "--seeds", "0",
        "--targets", "300", "--jobs", "1", "--mix", "thirds", "--rest",
    )  # fmt: skip
    assert [c["requires"] for c in report["mix"]] == [["A"], ["B"], ["A", "B"]]
    assert sum(c["share"] for c in report["mix"]) == 1.0
    (record,) = report["records"]
    # the solver's value of its optimum is the evaluator's: objective (11) both ways
    assert abs(record["gap_at_optimum"]) < 1e-9
    assert set(record["consolidating"]) == {"cold", "warm"}
    # the same targets through a live service: a fleet of both types, created without a
    # rule, learns as in process (no consolidation falls due before 300 targets here)
    rest = report["rest"]
    assert (rest["network"], rest["vehicles"], rest["seed"]) == ("drt", 4, 0)
    assert rest["rule"] == "consolidating"
    assert rest["in_process"] == record["consolidating"]["cold"]
    assert rest["gaps"] == rest["in_process"]
    assert "API docs at" in log  # the server's banner, kept off standard output
