"""``bench/cosim_report.py --render-only`` with nothing finished in its work folder ends
with a one-line error and leaves the report it would overwrite as it was."""

from __future__ import annotations

import importlib.util
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
WRITTEN = [ROOT / "docs" / "cosim.md", ROOT / "docs" / "figures" / "cosim" / "report.json"]


def test_render_only_without_finished_runs_writes_nothing(tmp_path: Path) -> None:
    before = {path: path.read_bytes() for path in WRITTEN}
    done = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "cosim_report.py"), "--render-only", "--quiet",
         "--workdir", str(tmp_path / "empty")],
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )  # fmt: skip
    after = {path: path.read_bytes() for path in WRITTEN}
    for path, data in before.items():  # put the report back if it was overwritten
        if after[path] != data:
            path.write_bytes(data)
    assert done.returncode == 2, done.stderr
    assert "no experiment has finished in" in done.stderr.strip().splitlines()[-1]
    assert after == before


def _report_module() -> Any:
    if str(ROOT / "bench") not in sys.path:  # as when it runs as a script
        sys.path.insert(0, str(ROOT / "bench"))
    spec = importlib.util.spec_from_file_location(
        "cosim_report", ROOT / "bench" / "cosim_report.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


def _row(mean: float, sd: float, expected: float) -> dict[str, float]:
    return {"mean_wait_s": mean, "mean_wait_sd_s": sd, "expected_wait_s": expected}


def test_a_missed_optimum_goal_says_where_the_references_stand() -> None:
    report = _report_module()
    figures = {"sa": _row(159.0, 6.0, 59.0), "optimum": _row(149.0, 9.0, 57.6)}
    (line,) = report._where_references_stand(figures, report.goal_checks(figures), 1000)
    # 59.0 / 57.6 - 1 = +2.43 %; 159 / 149 - 1 = +6.71 %, by hand
    assert "59.0 s from `sa`'s references" in line and "57.6 s" in line
    assert "(+2.4 %)" in line and "differ by +6.7 %" in line
    assert "of its 1000 historical requests" in line and "6 s (`sa`) and 9 s (`optimum`)" in line
    met = {"sa": _row(156.0, 6.0, 59.0), "optimum": _row(149.0, 9.0, 57.6)}  # 1.047: met
    assert report._where_references_stand(met, report.goal_checks(met), 1000) == []
    unknown = {"sa": _row(159.0, 6.0, math.nan), "optimum": _row(149.0, 9.0, 57.6)}
    assert report._where_references_stand(unknown, report.goal_checks(unknown), 1000) == []


def test_the_report_ends_with_the_sections_measured_by_their_own_commands() -> None:
    report = _report_module()
    names = [path.name for path in report.MEASURED_SECTIONS]
    assert names == ["stands.md", "other_networks.md", "travel_times.md"]
    sections = [path.read_text(encoding="utf-8") for path in report.MEASURED_SECTIONS]
    assert [text.splitlines()[0] for text in sections] == [
        "## Stands", "## Networks outside the report", "## With SUMO's current travel times",
    ]  # fmt: skip
    document = (ROOT / "docs" / "cosim.md").read_text(encoding="utf-8")
    assert document.endswith("".join("\n" + text for text in sections))


def test_the_report_from_saved_runs_shows_the_figures_the_full_run_drew() -> None:
    report = _report_module()
    drawn = report.drawn_figures("drt-persons-10")
    assert list(drawn) == ["waits", "positions", "objective"]
    assert all(path.is_file() and path.parent == report.FIGURES for path in drawn.values())
    assert report.drawn_figures("no-such-experiment") == {}
    document = (ROOT / "docs" / "cosim.md").read_text(encoding="utf-8")
    for kind, path in drawn.items():  # as the report links them
        assert f"![drt-persons-10 {kind}]({path.relative_to(ROOT / 'docs').as_posix()})" in document
