"""``bench/drift.py`` prints one JSON document whose summary is that of its records, at
the checkpoints of its drift, and refuses bad options before any work."""

from __future__ import annotations

import math
import statistics
from pathlib import Path

from tests.helpers import assert_bench_refuses, bench_report


def test_drift_report_is_its_records(tmp_path: Path) -> None:
    report, _ = bench_report(
        "drift.py", tmp_path, "--nets", "grid", "--vehicles", "2", "--seeds", "0,1",
        "--settle", "500", "--drift", "2000", "--hold", "1000", "--jobs", "1",
    )  # fmt: skip
    records = report["records"]
    assert [(r["network"], r["vehicles"], r["seed"]) for r in records] == [
        ("grid", 2, 0),
        ("grid", 2, 1),
    ]
    answers = ("consolidating", "probe", "recent_2000", "recent_4000")
    labels = ["settled", "drift 1/4", "drift 2/4", "drift 3/4", "drift 4/4", "+1000"]
    table = report["median_over_seeds"]["grid/2"]
    for answer in answers:
        for r in records:
            assert list(r[answer]) == labels
            assert all(math.isfinite(g) and g > -0.5 for g in r[answer].values())
        for label in labels:
            assert table[answer][label] == statistics.median(r[answer][label] for r in records)
        during = [(table[answer][label], f"grid/2@{label}") for label in labels[1:5]]
        assert tuple(report["worst_during_drift"][answer]) == max(during)


def test_drift_refuses_bad_options_before_any_work(tmp_path: Path) -> None:
    assert_bench_refuses(
        "drift.py",
        tmp_path,
        [
            (["--nets", "nosuch"], "'nosuch' is neither a known network"),
            (["--drift", "3000"], "--drift must be a positive multiple of 2000"),
            (["--hold", "0"], "--settle, --hold and --jobs must be at least 1"),
        ],
    )
