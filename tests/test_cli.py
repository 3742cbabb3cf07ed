"""The command line: real runs of small jobs, and bad input that ends with exit code 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest


def cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "routing_svc.cli", *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=cwd,
    )


def test_simulate_on_a_real_network_reports_the_gap_to_the_optimum() -> None:
    out = cli(
        "simulate", "--net", "drt", "--vehicles", "4", "--targets", "3000", "--start", "first",
        "--quiet",
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    curve = report["curve"]
    assert curve[-1]["targets"] == 3000
    optimum = report["optimum"]["objective"]
    # the exact optimum is a lower bound of every configuration's exact expected cost
    assert all(point["expected_cost"] >= optimum * (1 - 1e-9) for point in curve)
    assert report["gap"] == pytest.approx((curve[-1]["expected_cost"] - optimum) / optimum)
    assert curve[-1]["expected_cost"] < curve[0]["expected_cost"]
    assert len(report["positions"]) == 4
    # the first target (which may compile the kernels) is timed apart from the rest
    assert report["sa_first_target_seconds"] > 0 and report["sa_microseconds_per_target"] > 0


def test_simulate_where_the_vehicles_can_cover_every_demand_atom() -> None:
    # SUMO's Ingolstadt game network keeps a loop of four edges: the exact optimum of
    # eight vehicles for its hotspot demand costs nothing
    net = Path(__import__("sumo").SUMO_HOME) / "tools/game/fkk_in/ingolstadt.net.xml.gz"
    runs = {}
    for targets in ("100", "1000"):
        out = cli(
            "simulate", "--net", str(net), "--vehicles", "8", "--targets", targets,
            "--start", "random", "--quiet",
        )  # fmt: skip
        assert out.returncode == 0, out.stderr
        runs[targets] = json.loads(out.stdout)
    for report in runs.values():
        assert report["optimum"]["objective"] == 0.0 and report["optimum"]["proven_optimal"]
        assert report["curve"][0]["expected_cost"] > 0.0
    early, late = runs["100"], runs["1000"]
    # before its first consolidation the fleet is off an optimum of 0: no finite gap
    assert early["final_expected_cost"] > 0.0 and early["gap"] is None
    assert late["final_expected_cost"] == 0.0 and late["gap"] == 0.0


def test_simulate_on_the_plane_is_deterministic() -> None:
    args = ("simulate", "--plane", "--vehicles", "3", "--targets", "2000", "--quiet", "--seed", "3")
    first, second = cli(*args), cli(*args)
    assert first.returncode == 0, first.stderr
    a, b = json.loads(first.stdout), json.loads(second.stdout)
    assert a["positions"] == b["positions"] and a["curve"] == b["curve"]
    assert a["gap"] < 0.25


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("simulate", "--vehicles", "0"), "vehicles"),
        (("simulate", "--demand", "nowhere"), "demand"),
        (("simulate", "--net", "atlantis"), "atlantis"),
        (("simulate", "--start", "prior:2", "--vehicles", "5"), "start"),
        (("simulate", "--probe", "-1"), "--probe"),
        (("simulate", "--step-scale", "0"), "--step-scale"),
        (("replay", "--db", "/nonexistent/file.db"), "no database"),
    ],
)
def test_bad_input_is_a_one_line_error(args: tuple[str, ...], needle: str) -> None:
    out = cli(*args)
    assert out.returncode == 2
    assert needle in out.stderr.lower()
    assert "Traceback" not in out.stderr


def test_nets_lists_the_eclipse_sumo_networks() -> None:
    out = cli("nets", "--json")
    assert out.returncode == 0, out.stderr
    names = {n["name"] for n in json.loads(out.stdout)}
    assert {"drt", "grid", "spider", "oneway"} <= names
