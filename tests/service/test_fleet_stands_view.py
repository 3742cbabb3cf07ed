"""A fleet's stands as ``GET /v1/fleets/{id}`` shows them, on Bad Hersfeld with stands of
the shared parking file: positions against sumolib, capacities, and every vehicle at the
stand the assignment rule gives it (recomputed here); ``null`` for a fleet without stands."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sumolib
from fastapi.testclient import TestClient

from routing_svc.network import CompiledNetwork, RoadSpace, load_network
from routing_svc.network.stands import Stand, read_stands_file
from routing_svc.service.app import create_app
from routing_svc.service.settings import Settings
from routing_svc.types import NetPosition

SHARED = Path(__file__).resolve().parents[3] / "shared" / "nets"
BAD_HERSFELD = SHARED / "badhersfeld.net.xml.gz"
PARKING = SHARED / "badhersfeld.parking.add.xml"
CAPACITIES = (2, 1, 1, 2)


@pytest.fixture(scope="module")
def network() -> CompiledNetwork:
    return load_network(BAD_HERSFELD)


@pytest.fixture(scope="module")
def parking(network: CompiledNetwork) -> list[Stand]:
    """Four usable stands of the shared file, spread over it."""
    usable = read_stands_file(PARKING, network).usable
    return [usable[i] for i in (0, 100, 200, 300)]


@pytest.fixture
def client(db_url: str, tmp_path: Path) -> Iterator[TestClient]:
    settings = Settings(
        database_url=db_url,
        networks={"bh": str(BAD_HERSFELD)},
        data_dir=tmp_path / "networks",
    )
    with TestClient(create_app(settings)) as c:
        yield c


def fleet(fleet_id: str, network: CompiledNetwork, **extra: Any) -> dict[str, Any]:
    """Five vehicles on Bad Hersfeld at the start of spread-out edges."""
    edges = np.linspace(0, network.n_edges - 1, 5).astype(int).tolist()
    vehicles = [
        {"id": f"v{k}", "position": {"edge": network.edge_ids[e], "offset": 0.0}}
        for k, e in enumerate(edges)
    ]
    return {"id": fleet_id, "network": "bh", "rule": "paper", "vehicles": vehicles, **extra}


def expected_stands(
    network: CompiledNetwork, stands: list[tuple[NetPosition, int]], vehicles: list[dict[str, Any]]
) -> list[list[str]]:
    """Per stand, the vehicles the rule puts there: pairs (stand, vehicle) in ascending
    cost, then stand, then vehicle order; a pair is taken while the vehicle has no stand
    and the stand has room. Each stand's vehicles in id order."""
    references = [
        NetPosition(network.edge_index[v["reference"]["edge"]], v["reference"]["offset"])
        for v in vehicles
    ]
    costs = RoadSpace(network, cost="length").cost_matrix([p for p, _ in stands], references)
    pairs = sorted(
        (float(costs[i, k]), i, k) for i in range(len(stands)) for k in range(len(vehicles))
    )
    room = [c for _, c in stands]
    at: list[list[str]] = [[] for _ in stands]
    placed: set[int] = set()
    for _, i, k in pairs:
        if k not in placed and room[i] > 0:
            at[i].append(vehicles[k]["id"])
            placed.add(k)
            room[i] -= 1
    return [sorted(ids) for ids in at]


SUMO = sumolib.net.readNet(str(BAD_HERSFELD))


def check_stands(
    client: TestClient,
    answer: dict[str, Any],
    network: CompiledNetwork,
    given: list[tuple[Stand, int]],
) -> None:
    shown = answer["stands"]
    assert [(s["position"]["edge"], s["position"]["offset"]) for s in shown] == [
        (stand.edge, stand.offset) for stand, _ in given
    ]
    assert [s["capacity"] for s in shown] == [c for _, c in given]
    for s in shown:
        position = s["position"]
        shape = SUMO.getEdge(position["edge"]).getShape()
        x, y = sumolib.geomhelper.positionAtShapeOffset(shape, position["offset"])
        assert position["x"] == pytest.approx(x, abs=0.05)
        assert position["y"] == pytest.approx(y, abs=0.05)
    # described as the network describes any position
    resolved = client.post(
        "/v1/networks/bh/positions:resolve",
        json={"positions": [{"edge": stand.edge, "offset": stand.offset} for stand, _ in given]},
    )
    assert resolved.status_code == 200, resolved.text
    assert [s["position"] for s in shown] == resolved.json()["positions"]
    listed = [v for s in shown for v in s["vehicles"]]
    assert sorted(listed) == sorted(v["id"] for v in answer["vehicles"])  # each exactly once
    assert all(len(s["vehicles"]) <= s["capacity"] for s in shown)
    places = [(NetPosition(network.edge_index[stand.edge], stand.offset), c) for stand, c in given]
    assert [s["vehicles"] for s in shown] == expected_stands(network, places, answer["vehicles"])


def test_a_fleet_shows_its_stands_and_the_vehicles_at_each(
    client: TestClient, network: CompiledNetwork, parking: list[Stand]
) -> None:
    given = list(zip(parking, CAPACITIES, strict=True))
    stands = [{**stand.to_dict(), "capacity": c} for stand, c in given]
    created = client.post("/v1/fleets", json=fleet("bh1", network, stands=stands))
    assert created.status_code == 201, created.text
    check_stands(client, created.json(), network, given)
    assert client.get("/v1/fleets/bh1").json() == created.json()
    rng = np.random.default_rng(3)
    batch = [
        {"position": {"edge": network.edge_ids[int(e)], "offset": 0.0}}
        for e in rng.integers(network.n_edges, size=40)
    ]
    fed = client.post("/v1/fleets/bh1/targets:batch", json={"targets": batch})
    assert fed.status_code == 200, fed.text
    after = client.get("/v1/fleets/bh1").json()
    assert after["targets"] == 40
    check_stands(client, after, network, given)


def test_stands_at_one_position_are_shown_once_with_their_capacities_added(
    client: TestClient, network: CompiledNetwork, parking: list[Stand]
) -> None:
    first, second = parking[0], parking[1]
    stands = [
        {**first.to_dict(), "capacity": 2},
        {**second.to_dict(), "capacity": 1},
        {**first.to_dict(), "capacity": 3},
    ]
    created = client.post("/v1/fleets", json=fleet("bh2", network, stands=stands))
    assert created.status_code == 201, created.text
    check_stands(client, created.json(), network, [(first, 5), (second, 1)])


def test_a_fleet_without_stands_shows_null(client: TestClient, network: CompiledNetwork) -> None:
    created = client.post("/v1/fleets", json=fleet("free", network))
    assert created.status_code == 201, created.text
    assert created.json()["stands"] is None
    assert client.get("/v1/fleets/free").json()["stands"] is None
    assert client.get("/v1/fleets").json()["items"][0]["stands"] is None
    schema = client.get("/openapi.json").json()["components"]["schemas"]
    assert "stands" in schema["FleetAnswer"]["required"]
    assert set(schema["StandAnswer"]["required"]) == {"position", "capacity", "vehicles"}
