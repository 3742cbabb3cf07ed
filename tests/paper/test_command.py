"""The ``paper`` subcommand writes a JSON and a PNG per experiment."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from routing_svc.paper.command import main
from routing_svc.paper.result import ExperimentResult, jsonable, seed_generators


def test_the_command_writes_a_json_and_a_png(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["paper", "heterogeneous", "--quick", "--seeds", "1", "--out", str(tmp_path)])
    assert code == 0
    record = json.loads((tmp_path / "heterogeneous.json").read_text())
    assert (
        record["command"] == f"routing-svc paper heterogeneous --out {tmp_path} --seeds 1 --quick"
    )
    assert record["params"]["seeds"] == 1
    assert record["summary"]["seeds_with_a_pair_near_6_6"] == 1
    png = (tmp_path / "heterogeneous.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 10_000
    line = json.loads(capsys.readouterr().out.strip())
    assert line["experiment"] == "heterogeneous" and "seconds" in line


def test_bad_seed_count_is_refused(tmp_path: Path) -> None:
    assert main(["paper", "fading", "--seeds", "0", "--out", str(tmp_path)]) == 2
    assert not list(tmp_path.iterdir())


def test_results_round_trip_through_json() -> None:
    result = ExperimentResult(
        name="x",
        title="t",
        params={"a": np.float64(1.5), "n": np.int64(3)},
        summary={"v": float("nan"), "ok": np.bool_(True)},
        series={"curve": np.arange(3.0), "nested": {"k": (1.0, 2.0)}},
    )
    data = json.loads(json.dumps(result.to_json(), allow_nan=False))
    assert data["summary"] == {"v": None, "ok": True}
    assert data["series"]["curve"] == [0.0, 1.0, 2.0]
    assert ExperimentResult.from_json(data).params == {"a": 1.5, "n": 3}
    assert jsonable(1.234567891) == 1.23457


def test_seed_generators_are_independent_and_reproducible() -> None:
    first = [g.random() for g in seed_generators(7, 3)]
    again = [g.random() for g in seed_generators(7, 3)]
    assert first == again and len(set(first)) == 3
