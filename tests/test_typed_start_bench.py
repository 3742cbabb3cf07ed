"""``bench/typed_start.py`` prints one JSON document whose summary is that of its records,
and refuses bad options before any work."""

from __future__ import annotations

import math
import statistics
from pathlib import Path

from tests.helpers import assert_bench_refuses, bench_report


def test_typed_start_report_is_its_records(tmp_path: Path) -> None:
    report, _ = bench_report(
        "typed_start.py", tmp_path, "--nets", "grid", "--calls", "60", "--seeds", "0,1,2"
    )
    records = report["records"]
    assert [(r["network"], r["calls"], r["seed"]) for r in records] == [
        ("grid", 60, 0),
        ("grid", 60, 1),
        ("grid", 60, 2),
    ]
    for r in records:
        assert set(r["gaps"]) == {"own_calls", "all_calls"}
        assert all(math.isfinite(g) and g > -0.5 for g in r["gaps"].values())
    summary = report["by_calls"]["60"]
    medians = {
        rule: statistics.median(r["gaps"][rule] for r in records)
        for rule in ("own_calls", "all_calls")
    }
    for rule, median in medians.items():
        assert summary[rule]["worst"] == [median, "grid/hotspots:3/60"]
        assert summary[rule]["mean_of_medians"] == median
    assert summary["ratio_own_over_all"] == medians["own_calls"] / medians["all_calls"]


def test_typed_start_refuses_bad_options_before_any_work(tmp_path: Path) -> None:
    assert_bench_refuses(
        "typed_start.py",
        tmp_path,
        [
            (["--nets", "nosuch"], "'nosuch' is neither a known network"),
            (["--calls", "5"], "a history needs at least 8 calls"),
            (["--demand", "bogus:1"], "--demand must be"),
        ],
    )
