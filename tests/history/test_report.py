"""The report against hand computations, and the command against a live server."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from routing_svc.history import (
    ImportResult,
    InProcessHistoryClient,
    place_locally,
    read_calls,
    replay_history,
)
from routing_svc.history.report import service_levels, write_report
from routing_svc.network import CompiledNetwork
from routing_svc.types import NetPosition
from tests.history.conftest import cli, fleet_at, random_calls, write_csv


def test_service_levels_by_hour_match_a_hand_computation() -> None:
    costs = np.array([100.0, 200.0, 400.0, 700.0, 1000.0])
    hours = np.array([8, 8, 8, 9, 9])
    levels = service_levels(costs, hours, thresholds=(300.0, 900.0))
    eight, nine = levels["by_hour"]
    assert (eight["hour"], eight["calls"], nine["hour"], nine["calls"]) == (8, 3, 9, 2)
    assert eight["within"] == {"300": 2 / 3, "900": 1.0}
    assert nine["within"] == {"300": 0.0, "900": 0.5}
    assert (eight["p50"], eight["p90"]) == (200.0, pytest.approx(360.0))  # 200 + 0.8 * 200
    assert (nine["p50"], nine["p95"]) == (850.0, pytest.approx(985.0))
    assert levels["all"]["p50"] == 400.0


def import_on_one_edge(
    tmp_path: Path,
    client: InProcessHistoryClient,
    e: int,
    rows: list[list[Any]],
    *,
    chunk_size: int,
) -> tuple[ImportResult, dict[str, Any]]:
    """Import ``rows`` (time, edge, offset on edge ``e`` of ``drt``) into fleet ``f`` and
    write its report into ``tmp_path / "report"``."""
    path = write_csv(tmp_path / "calls.csv", ["time", "edge", "offset"], rows)
    table = read_calls(path)
    entry = client.service.network("drt")
    start = client.get_fleet("f")
    placed = place_locally(table, entry, vehicle_types=["default"] * len(start["vehicles"]))
    result = replay_history(table, placed, client, "f", progress=False, chunk_size=chunk_size)
    report = write_report(
        tmp_path / "report",
        entry,
        fleet=start,
        summary=result.summary(),
        targets=[NetPosition(e, o) for o in placed.offsets],
        costs=result.costs,
        hours=table.hours[result.order],
        checkpoints=result.checkpoints,
    )
    return result, report


def test_the_report_of_a_tiny_history_matches_a_hand_computation(
    tmp_path: Path, client: InProcessHistoryClient, drt: CompiledNetwork
) -> None:
    # five calls at 10 m and one at 20 m along one edge, one vehicle waiting at 10 m:
    # the p-median is that vehicle's place, at cost (1/6) * 10 m
    e = int(np.argmax(drt.length))
    edge = drt.edge_ids[e]
    rows = [[f"2024-03-01T0{h}:00:00", edge, 10.0] for h in (7, 7, 8, 8, 9)]
    rows.append(["2024-03-01T09:30:00", edge, 20.0])
    client.create_fleet(fleet_at([(edge, 10.0)], rule="consolidating"))
    result, report = import_on_one_edge(tmp_path, client, e, rows, chunk_size=2)
    gap = report["gap"]
    assert gap["optimum"]["objective"] == pytest.approx(10.0 / 6.0)
    assert gap["curve"][0]["expected_cost"] == pytest.approx(10.0 / 6.0)
    assert gap["curve"][0]["gap"] == pytest.approx(0.0, abs=1e-12)
    assert [c["calls"] for c in gap["curve"]] == [0, 2, 4, 6]
    # the first call is where the vehicle waits: cost 0
    assert result.costs[0] == 0.0
    by_hour = {h["hour"]: h["calls"] for h in report["service_levels"]["by_hour"]}
    assert by_hour == {7: 2, 8: 2, 9: 2}
    saved = json.loads((tmp_path / "report" / "report.json").read_text())
    assert saved["gap"]["optimum"]["objective"] == gap["optimum"]["objective"]
    for name in ("history_gap.png", "history_service_levels.png", "history_references.png"):
        assert (tmp_path / "report" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_history_of_no_more_places_than_vehicles_has_an_optimum_of_zero(
    tmp_path: Path, client: InProcessHistoryClient, drt: CompiledNetwork
) -> None:
    # calls at 10 m and 20 m along one edge, two vehicles at 5 m and 10 m: the p-median
    # puts one on each place (cost 0), the fleet serves the call at 20 m from 10 m
    e = int(np.argmax(drt.length))
    edge = drt.edge_ids[e]
    rows = [[f"2024-03-01T0{h}:00:00", edge, 10.0] for h in (7, 8)]
    rows.append(["2024-03-01T09:00:00", edge, 20.0])
    client.create_fleet(fleet_at([(edge, 5.0), (edge, 10.0)], rule="paper"))
    _, report = import_on_one_edge(tmp_path, client, e, rows, chunk_size=1)
    gap = report["gap"]
    assert gap["optimum"]["objective"] == 0.0
    first = gap["curve"][0]
    assert first["expected_cost"] == pytest.approx(10.0 / 3.0)  # the call at 20 m, from 10 m
    assert first["gap"] is None  # no finite relative gap to an optimum of 0
    assert all(c["gap"] is None or c["expected_cost"] == 0.0 for c in gap["curve"])
    saved = json.loads((tmp_path / "report" / "report.json").read_text())
    assert saved["gap"]["curve"][0]["gap"] is None
    assert (tmp_path / "report" / "history_gap.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_live_server_imports_what_the_process_imports(
    tmp_path: Path, drt: CompiledNetwork, live_server: Callable[[], str]
) -> None:
    calls = random_calls(drt, 80, seed=5)
    rows: list[list[object]] = [[c["time"], c["lon"], c["lat"]] for c in calls]
    rows[2][1:3] = [0.0, 0.0]  # line 4: off the map
    clean = write_csv(tmp_path / "clean.csv", ["time", "lon", "lat"], rows[:2] + rows[3:])
    path = write_csv(tmp_path / "calls.csv", ["time", "lon", "lat"], rows)
    url = live_server()
    remote = ["--service-url", url, "--fleet", "f", "--quiet"]
    created = cli("history", "create-fleet", str(clean), *remote, "--net", "drt", "--vehicles", "3")
    assert created.returncode == 0, created.stderr
    refused = cli("history", "import", str(path), *remote)
    assert refused.returncode == 2 and "line 4:" in refused.stderr
    skip = ["--on-bad-row", "skip", "--chunk-size", "30"]
    out = cli(
        "history",
        "import",
        str(path),
        *remote,
        *skip,
        "--report",
        str(tmp_path / "r"),
        "--net",
        "drt",
    )
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert [r["line"] for r in summary["bad_rows"]] == [4]
    assert (summary["calls_applied"], summary["chunks"], summary["version_after"]) == (79, 3, 80)
    assert summary["service_levels"]["calls"] == 79
    assert (tmp_path / "r" / "history_references.png").is_file()
    again = json.loads(cli("history", "import", str(path), *remote, *skip).stdout)
    assert (again["calls_applied"], again["version_after"]) == (0, 80)
