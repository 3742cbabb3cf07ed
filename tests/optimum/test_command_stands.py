"""``routing-svc optimum --stands`` on Bad Hersfeld with the shared parking file: the
answer against enumeration of every pair of stands, the free optimum against the plain
command, and a one-line error for a stands file that cannot hold the fleet."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from routing_svc.demand import from_weights_file
from routing_svc.network import CompiledNetwork, RoadSpace, load_network
from routing_svc.network.stands import read_stands_file
from routing_svc.optimum import expected_cost
from routing_svc.types import NetPosition

SHARED = Path(__file__).resolve().parents[3] / "shared" / "nets"
BAD_HERSFELD = SHARED / "badhersfeld.net.xml.gz"
PARKING = SHARED / "badhersfeld.parking.add.xml"


@pytest.fixture(scope="module")
def network() -> CompiledNetwork:
    return load_network(BAD_HERSFELD)


@pytest.fixture
def weights(tmp_path: Path, network: CompiledNetwork) -> Path:
    """Demand on twelve random edges of Bad Hersfeld."""
    rng = np.random.default_rng(1)
    edges = rng.choice(network.n_edges, size=12, replace=False)
    path = tmp_path / "weights.json"
    weight = rng.uniform(1, 5, 12)
    path.write_text(
        json.dumps({network.edge_ids[int(e)]: float(w) for e, w in zip(edges, weight, strict=True)})
    )
    return path


def optimum(*args: str) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "routing_svc.cli", "optimum", "--net", str(BAD_HERSFELD)]
    return subprocess.run([*command, *args], capture_output=True, text=True, timeout=300)


def test_the_optimum_over_the_stands_of_the_parking_file(
    network: CompiledNetwork, weights: Path
) -> None:
    args = ("--vehicles", "2", "--demand", f"weights:{weights}", "--max-sites", "200")
    done = optimum(*args, "--stands", str(PARKING))
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    reading = read_stands_file(PARKING, network)
    assert report["stands"] == {
        "file": PARKING.name,
        "usable": len(reading.usable),
        "dropped": len(reading.dropped),
        "capacity": reading.capacity,
    }
    places = sorted({(s.edge, s.offset) for s in reading.usable})
    shown = [(p["edge"], p["offset"]) for p in report["positions"]]
    assert len(shown) == 2 and set(shown) <= set(places)
    space = RoadSpace(network, cost="length")
    demand = from_weights_file(network, weights)
    at = [NetPosition(network.edge_index[e], o) for e, o in shown]
    value = expected_cost(space, at, np.ones(2), demand)
    assert report["objective"] == pytest.approx(value, rel=1e-12)
    # every pair of distinct stands, enumerated
    costs = space.cost_matrix(
        [NetPosition(network.edge_index[e], o) for e, o in places], list(demand.positions)
    )
    w = np.asarray(demand.weights, dtype=np.float64)
    best = min(
        float((np.minimum(costs[a], costs[a + 1 :]) @ w).min()) for a in range(len(places) - 1)
    )
    assert report["objective"] == pytest.approx(best, rel=1e-9)
    free = optimum(*args)
    assert free.returncode == 0, free.stderr
    assert report["free_objective"] == json.loads(free.stdout)["objective"]
    assert report["ratio"] == pytest.approx(report["objective"] / report["free_objective"])
    assert {k for k in json.loads(free.stdout)} | {"stands", "free_objective", "ratio"} == set(
        report
    )


def write(path: Path, body: str) -> Path:
    path.write_text(f"<additional>\n{body}\n</additional>\n")
    return path


def test_stands_that_cannot_hold_the_fleet_end_with_one_line(
    tmp_path: Path, network: CompiledNetwork, weights: Path
) -> None:
    usable = read_stands_file(PARKING, network).usable
    lanes = [f"{s.edge}_0" for s in usable[:2]]
    nowhere = write(
        tmp_path / "nowhere.add.xml",
        '<parkingArea id="a" lane="no_such_edge_0" roadsideCapacity="5"/>',
    )
    small = write(
        tmp_path / "small.add.xml",
        "\n".join(
            f'<parkingArea id="p{i}" lane="{lane}" roadsideCapacity="1"/>'
            for i, lane in enumerate(lanes)
        ),
    )
    cases = [
        (tmp_path / "missing.add.xml", "no stands file at"),
        (nowhere, "no stand of"),
        (small, "3 vehicles exceed the total capacity 2 of the stands"),
    ]
    for path, message in cases:
        done = optimum("--vehicles", "3", "--demand", f"weights:{weights}", "--stands", str(path))
        assert done.returncode == 2, (path, done.stdout)
        assert done.stdout == ""
        lines = done.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("routing-svc optimum: "), done.stderr
        assert message in lines[0]
    assert (
        "no_such_edge"
        in optimum(
            "--vehicles", "1", "--demand", f"weights:{weights}", "--stands", str(nowhere)
        ).stderr
    )
