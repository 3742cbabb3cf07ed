"""``routing-svc optimum`` end to end on the DRT network, through ``routing_svc.cli``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from routing_svc.cli import main
from routing_svc.demand import from_weights_file, uniform_by_length
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork, RoadSpace
from routing_svc.optimum import candidate_sites, expected_cost, solve_demand
from routing_svc.optimum import solve as solve_module
from routing_svc.types import NetPosition
from tests.optimum.conftest import DRT_NET


@pytest.fixture
def cache(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """Compiled networks go to a cache private to this test session."""
    root = tmp_path_factory.getbasetemp() / "optimum-command-cache"
    monkeypatch.setenv("ROUTING_SVC_CACHE", str(root))


def run_cli(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(["optimum", "--net", str(DRT_NET), *args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.usefixtures("cache")
def test_exact_optimum_report(
    capsys: pytest.CaptureFixture[str], drt_network: CompiledNetwork
) -> None:
    code, out, err = run_cli(capsys, "--vehicles", "3", "--max-sites", "300")
    assert code == 0, err
    report = json.loads(out)
    assert report["method"] == "milp" and report["proven_optimal"] is True
    assert report["n_sites"] <= 300 and report["n_demand"] == len(uniform_by_length(drt_network))
    assert report["unit"] == "m" and len(report["positions"]) == 3
    positions = [
        NetPosition(drt_network.edge_index[p["edge"]], p["offset"]) for p in report["positions"]
    ]
    space = RoadSpace(drt_network)
    for p, shown in zip(positions, report["positions"], strict=True):
        assert space.xy(p) == pytest.approx((shown["x"], shown["y"]))
    demand = uniform_by_length(drt_network)
    value = expected_cost(space, positions, np.ones(3), demand)
    assert report["objective"] == pytest.approx(value, rel=1e-12)
    assert report["lower_bound"] == pytest.approx(value, rel=1e-9)


@pytest.mark.usefixtures("cache")
def test_hotspots_heuristic_and_time_costs(capsys: pytest.CaptureFixture[str]) -> None:
    args = (
        "--vehicles",
        "4",
        "--demand",
        "hotspots:2",
        "--method",
        "heuristic",
        "--max-sites",
        "900",
    )
    code, out, err = run_cli(capsys, *args, "--cost", "time", "--seed", "5")
    assert code == 0, err
    report = json.loads(out)
    assert report["method"] == "heuristic" and report["unit"] == "s"
    assert report["demand"] == "hotspots:2" and len(report["positions"]) == 4
    again = json.loads(run_cli(capsys, *args, "--cost", "time", "--seed", "5")[1])
    assert again["positions"] == report["positions"]


@pytest.mark.usefixtures("cache")
def test_weights_file_demand(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, drt_network: CompiledNetwork
) -> None:
    """As many vehicles as demand atoms: every atom gets a vehicle, the cost is 0."""
    edges = [drt_network.edge_ids[int(e)] for e in np.argsort(drt_network.length)[-3:]]
    path = tmp_path / "weights.csv"
    path.write_text(f"edge,weight\n{edges[0]},2\n{edges[1]},1\n{edges[2]},1\n")
    atoms = len(from_weights_file(drt_network, path))
    code, out, err = run_cli(capsys, "--vehicles", str(atoms), "--demand", str(path))
    assert code == 0, err
    report = json.loads(out)
    assert report["demand"] == "weights_file:weights.csv" and report["n_demand"] == atoms
    assert report["objective"] == 0.0
    assert {p["edge"] for p in report["positions"]} == set(edges)


@pytest.mark.usefixtures("cache")
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--vehicles", "0"), "--vehicles must be >= 1"),
        (("--vehicles", "5", "--max-sites", "3"), "exceeds the 3 distinct candidate sites"),
        (("--vehicles", "2", "--demand", "nowhere.csv"), "--demand must be"),
        (("--vehicles", "2", "--demand", "hotspots:x"), "integer K >= 1"),
        (("--vehicles", "2", "--max-sites", "0"), "--max-sites must be >= 1"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(
    capsys: pytest.CaptureFixture[str], args: tuple[str, ...], message: str
) -> None:
    code, out, err = run_cli(capsys, *args)
    assert code == 2 and out == ""
    assert message in err and len(err.strip().splitlines()) == 1
    assert "Traceback" not in err


@pytest.mark.usefixtures("cache")
def test_missing_network_and_bad_weights_file(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code = main(["optimum", "--net", str(tmp_path / "missing.net.xml"), "--vehicles", "2"])
    err = capsys.readouterr().err
    assert code == 2 and "missing.net.xml" in err and len(err.strip().splitlines()) == 1
    bad = tmp_path / "bad.csv"
    bad.write_text("edge,weight\nno-such-edge,1\n")
    code, _, err = run_cli(capsys, "--vehicles", "2", "--demand", str(bad))
    assert code == 2 and "bad.csv line 2" in err and "no-such-edge" in err


@pytest.mark.usefixtures("cache")
def test_without_max_sites_a_large_problem_is_offered_the_sites_its_matrix_budget_holds(
    capsys: pytest.CaptureFixture[str],
    drt_network: CompiledNetwork,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    atoms = len(uniform_by_length(drt_network))
    monkeypatch.setattr(solve_module, "MATRIX_BYTES", 8 * atoms * 200)
    code, out, err = run_cli(capsys, "--vehicles", "3")
    assert code == 0, err
    report = json.loads(out)
    assert report["candidate_sites"] > 200 and report["n_sites"] <= 200
    code, out, err = run_cli(capsys, "--vehicles", "3", "--max-sites", "200")
    assert code == 0, err
    explicit = json.loads(out)
    assert report["positions"] == explicit["positions"]
    assert report["objective"] == explicit["objective"]


@pytest.mark.usefixtures("cache")
def test_max_sites_never_exceeds_the_budget_and_given_sites_over_it_are_refused(
    capsys: pytest.CaptureFixture[str],
    drt_network: CompiledNetwork,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    demand = uniform_by_length(drt_network)
    atoms = len(demand)
    monkeypatch.setattr(solve_module, "MATRIX_BYTES", 8 * atoms * 200)
    code, out, err = run_cli(capsys, "--vehicles", "3", "--max-sites", "1000")
    assert code == 0, err
    assert json.loads(out)["n_sites"] <= 200
    space = RoadSpace(drt_network)
    sites = candidate_sites(drt_network, demand, max_sites=201)
    assert len(sites) == 201
    with pytest.raises(InvalidInput, match=f"201 sites x {atoms} demand atoms") as refused:
        solve_demand(space, demand, 3, sites=sites)
    assert "offer at most 200 sites" in str(refused.value)
    assert len(solve_demand(space, demand, 3, sites=sites[:200]).sites) == 200
