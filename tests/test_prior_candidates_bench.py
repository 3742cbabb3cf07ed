"""``bench/prior_candidates.py`` prints one JSON document whose summary is that of its
records, and whose cross-validated rule takes the gap of the rule it chose."""

from __future__ import annotations

import math
import statistics
from pathlib import Path

from tests.helpers import assert_bench_refuses, bench_report


def test_prior_candidates_report_is_its_records(tmp_path: Path) -> None:
    report, _ = bench_report(
        "prior_candidates.py", tmp_path, "--nets", "grid", "--vehicles", "2",
        "--demands", "hotspots:3,uniform", "--samples", "300", "--seeds", "0,1",
    )  # fmt: skip
    records = report["records"]
    assert len(records) == 4
    for r in records:
        gaps = r["gaps"]
        assert set(gaps) == {"default", "ends", "cross_validated"}
        assert all(math.isfinite(g) and g > -0.5 for g in gaps.values())
        assert gaps["cross_validated"] == gaps[r["cross_validated_choice"]]
    summary = report["by_sample_size"]["300"]
    for rule in ("default", "ends", "cross_validated"):
        medians = [
            statistics.median(r["gaps"][rule] for r in records if r["demand"] == demand)
            for demand in ("hotspots:3", "uniform")
        ]
        assert summary[rule]["mean_of_medians"] == statistics.fmean(medians)
        assert summary[rule]["worst"][0] == max(medians)
    assert summary["default"]["ratio_to_default"] == 1.0


def test_prior_candidates_refuses_bad_options_before_any_work(tmp_path: Path) -> None:
    assert_bench_refuses(
        "prior_candidates.py",
        tmp_path,
        [
            (["--nets", "nosuch"], "'nosuch' is neither a known network"),
            (["--vehicles", "0"], "a fleet has at least one vehicle"),
            (
                ["--samples", "5", "--vehicles", "8"],
                "at least as many targets as the largest fleet",
            ),
            (["--demands", "bogus:1"], "--demand must be"),
        ],
    )
