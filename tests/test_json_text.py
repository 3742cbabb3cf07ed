"""What the commands print and write is standard JSON: a number that is not finite is
``null``, and a saved co-simulation run reads back to the same summary."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from routing_svc.json_text import json_text
from routing_svc.sim.measures import PolicyRun


def strict_loads(text: str) -> Any:
    """JSON as RFC 8259 has it: ``Infinity`` and ``NaN`` are refused."""

    def refuse(constant: str) -> None:
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def test_strict_loads_refuses_what_json_dumps_writes_by_default() -> None:
    with pytest.raises(ValueError, match="Infinity"):
        strict_loads(json.dumps({"p90": math.inf}))


def test_non_finite_numbers_are_null_at_any_depth_and_the_rest_is_unchanged() -> None:
    value = {
        "p90": math.inf,
        "low": -math.inf,
        "mean": math.nan,
        "numpy": np.float64(np.inf),
        "pairs": [(1.5, math.nan), (2, "x")],
        "nested": {"ok": 0.25, "flag": True, "none": None, "n": 3},
    }
    assert strict_loads(json_text(value, indent=2)) == {
        "p90": None,
        "low": None,
        "mean": None,
        "numpy": None,
        "pairs": [[1.5, None], [2, "x"]],
        "nested": {"ok": 0.25, "flag": True, "none": None, "n": 3},
    }
    finite = {"a": [1.0, 2.5e-300, -0.0], "b": "Infinity"}
    assert json_text(finite, sort_keys=True) == json.dumps(finite, sort_keys=True)


def test_a_run_with_requests_never_served_is_saved_as_json_and_reads_back_the_same() -> None:
    waits = [(0.0, 30.0, True), (10.0, 50.0, True), (20.0, 400.0, True), (30.0, 0.0, False)]
    run = PolicyRun(
        policy="sa", seed=0, requests=4, served=3, mean_wait=160.0,
        mean_wait_second_half=math.nan, empty_km=1.5, driven_km=2.0, fallbacks=0,
        queued=1, failed=0, sim_seconds=600.0, wall_seconds=2.0, tripinfo="t.xml",
        vehicles=2, request_hours=0.25, waits=waits,
        predicted=[(12.0, False), (math.nan, False), (40.0, True), (math.nan, False)],
    )  # fmt: skip
    summary = run.summary()
    assert summary["p90_wait_s"] == math.inf and math.isnan(summary["busy_fraction"])
    saved = strict_loads(json_text(run.to_json()))
    assert saved["p90_wait_s"] is None and saved["mean_wait_second_half_s"] is None
    again = PolicyRun.from_json(saved)
    assert json_text(again.summary()) == json_text(summary)
    assert again.summary()["p90_wait_s"] == math.inf  # derived again from the waits
    assert [t for t, _ in again.predicted[0::2]] == [12.0, 40.0]
    assert all(math.isnan(t) for t, _ in again.predicted[1::2])
