"""A typed fleet with a requirement mix: its gap is to the heterogeneous optimum (HTTP)."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from routing_svc.demand import DemandDistribution
from routing_svc.demand import network as network_demand
from routing_svc.network import RoadSpace, load_network
from routing_svc.optimum import expected_cost
from routing_svc.optimum.heterogeneous import RequirementClass, heterogeneous_cost
from routing_svc.types import NetPosition
from tests.helpers import DRT, targets

NET = load_network(DRT)
SPACE = RoadSpace(NET, cost="length")
EDGE_WEIGHTS = {10: 1.0, 200: 2.0, 400: 1.0, 550: 0.5}
MIX: list[dict[str, Any]] = [
    {"requires": ["A"], "share": 0.5},
    {"requires": ["A", "B"], "share": 0.3},
    {"requires": ["A", "A"], "share": 0.2},
]
VEHICLES = [("v1", "A", 1.0, 0), ("v2", "A", 1.5, 100), ("v3", "B", 1.0, 300)]


def edge(i: int) -> str:
    return NET.edge_ids[i]


def reference_demand(requirements: list[dict[str, Any]] | None = MIX) -> dict[str, Any]:
    spec: dict[str, Any] = {
        "kind": "weights",
        "weights": {edge(e): w for e, w in EDGE_WEIGHTS.items()},
    }
    if requirements is not None:
        spec["requirements"] = requirements
    return spec


def fleet_body(
    fleet_id: str, positions: list[dict[str, Any]] | None = None, **extra: Any
) -> dict[str, Any]:
    if positions is None:
        positions = [{"edge": edge(e), "offset": 0.0} for *_, e in VEHICLES]
    body: dict[str, Any] = {
        "id": fleet_id,
        "network": "drt",
        "vehicles": [
            {"id": i, "type": t, "speed": s, "position": p}
            for (i, t, s, _), p in zip(VEHICLES, positions, strict=True)
        ],
        "reference_demand": reference_demand(),
    }
    body.update(extra)
    return body


def weighted_demand() -> DemandDistribution[NetPosition]:
    """The "weights" reference demand: each edge's weight spread evenly along it."""
    edges = np.array(sorted(EDGE_WEIGHTS), dtype=np.int64)
    per_metre = np.zeros(NET.n_edges)
    for e, w in EDGE_WEIGHTS.items():
        per_metre[e] = w / float(NET.length[e])
    at, offsets, pieces = network_demand.edge_pieces(
        NET, spacing=network_demand.DEFAULT_SPACING, edges=edges
    )
    positions = tuple(NetPosition(int(e), float(o)) for e, o in zip(at, offsets, strict=True))
    return DemandDistribution.from_masses("weights", positions, pieces * per_metre[at])


def exact_cost(fleet: dict[str, Any]) -> float:
    """The heterogeneous expected cost of a fleet's current positions, from scratch."""
    vehicles = fleet["vehicles"]
    positions = [
        NetPosition(NET.edge_index[v["position"]["edge"]], float(v["position"]["offset"]))
        for v in vehicles
    ]
    mix = [RequirementClass(tuple(c["requires"]), c["share"]) for c in MIX]
    return heterogeneous_cost(
        SPACE,
        positions,
        [v["type"] for v in vehicles],
        [v["speed"] for v in vehicles],
        weighted_demand(),
        mix,
    )


def test_the_gap_of_a_typed_fleet_is_to_the_heterogeneous_optimum(client: TestClient) -> None:
    r = client.post("/v1/fleets", json=fleet_body("typed"))
    assert r.status_code == 201, r.text
    assert r.json()["reference_demand"]["requirements"] == MIX
    optimum = client.get("/v1/fleets/typed/metrics").json()["optimum"]
    assert optimum["kind"] == "heterogeneous"
    value = exact_cost(client.get("/v1/fleets/typed").json())
    assert optimum["expected_cost"] == pytest.approx(value, rel=1e-12)
    assert optimum["objective"] <= value
    assert optimum["gap"] == pytest.approx((value - optimum["objective"]) / optimum["objective"])

    created = client.get("/v1/fleets/typed/events").json()["items"][0]
    stored = created["payload"]["reference"]["optimum"]
    assert stored["kind"] == "heterogeneous" and len(stored["positions"]) == len(VEHICLES)
    r = client.post("/v1/fleets", json=fleet_body("at-optimum", stored["positions"]))
    assert r.status_code == 201, r.text
    at_optimum = client.get("/v1/fleets/at-optimum/metrics").json()["optimum"]
    assert at_optimum["objective"] == pytest.approx(optimum["objective"], rel=1e-12)
    assert exact_cost(r.json()) == pytest.approx(optimum["objective"], rel=1e-9)
    assert at_optimum["gap"] == pytest.approx(0.0, abs=1e-9)


def test_a_homogeneous_fleet_keeps_the_pmedian(client: TestClient) -> None:
    body = fleet_body("plain", reference_demand=reference_demand(None))
    for v in body["vehicles"]:
        v["type"], v["speed"] = "default", 1.0
    r = client.post("/v1/fleets", json=body)
    assert r.status_code == 201, r.text
    assert client.get("/v1/fleets/plain/metrics").json()["optimum"]["kind"] == "p-median"
    stored = client.get("/v1/fleets/plain/events").json()["items"][0]["payload"]["reference"]
    assert "requirements" not in stored["demand"]
    assert "kind" not in stored["optimum"] and "positions" not in stored["optimum"]


@pytest.mark.parametrize(
    "requirements",
    [
        [{"requires": ["C"], "share": 1.0}],
        [{"requires": ["B", "B"], "share": 1.0}],
        [{"requires": ["A"], "share": 0.0}],
        [{"requires": ["A"], "share": -0.5}],
        [{"requires": ["A"]}],
        [{"requires": [""], "share": 1.0}],
        [{"requires": ["A"], "share": 1.0, "extra": 1}],
        [],
    ],
)
def test_a_bad_mix_is_rejected_and_creates_nothing(
    client: TestClient, requirements: list[dict[str, Any]]
) -> None:
    body = fleet_body("bad", reference_demand=reference_demand(requirements))
    r = client.post("/v1/fleets", json=body)
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    assert client.get("/v1/fleets/bad").status_code == 404
    assert client.get("/v1/fleets").json()["items"] == []


STAND_EDGES = (5, 10, 200, 400, 550)


def test_a_fleet_with_stands_has_its_gap_to_the_optimum_over_them(client: TestClient) -> None:
    stands = [{"edge": edge(e), "offset": 0.0, "capacity": 1} for e in STAND_EDGES]
    body = fleet_body("parked", reference_demand=reference_demand(None), stands=stands)
    for v in body["vehicles"]:
        v["type"], v["speed"] = "default", 1.0
    r = client.post("/v1/fleets", json=body)
    assert r.status_code == 201, r.text
    r = client.post("/v1/fleets/parked/targets:batch", json={"targets": targets(5, 40)})
    assert r.status_code == 200, r.text
    optimum = client.get("/v1/fleets/parked/metrics").json()["optimum"]
    assert optimum["kind"] == "stands"
    demand = weighted_demand()
    sites = [NetPosition(e, 0.0) for e in STAND_EDGES]
    # brute force over every three of the five stands (capacity 1 each)
    best = min(
        expected_cost(SPACE, list(chosen), np.ones(3), demand)
        for chosen in itertools.combinations(sites, 3)
    )
    assert optimum["objective"] == pytest.approx(best, rel=1e-9)
    # the gap is that of the stands where the vehicles wait
    view = client.get("/v1/fleets/parked").json()["stands"]
    waiting = [
        NetPosition(NET.edge_index[s["position"]["edge"]], float(s["position"]["offset"]))
        for s in view
        for _ in s["vehicles"]
    ]
    assert len(waiting) == 3
    value = expected_cost(SPACE, waiting, np.ones(3), demand)
    assert optimum["expected_cost"] == pytest.approx(value, rel=1e-12)
    assert optimum["gap"] == pytest.approx((value - best) / best, rel=1e-9, abs=1e-12)
    assert optimum["gap"] >= -1e-12
    # the same fleet without stands is measured against the free p-median, which is lower
    free_body = {k: v for k, v in body.items() if k != "stands"} | {"id": "free"}
    assert client.post("/v1/fleets", json=free_body).status_code == 201
    free = client.get("/v1/fleets/free/metrics").json()["optimum"]
    assert free["kind"] == "p-median" and free["objective"] <= best * (1 + 1e-9)
