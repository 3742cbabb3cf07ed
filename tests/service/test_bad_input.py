"""Bad input: a clear 4xx problem+json, and no state change."""

from __future__ import annotations

import gzip
from collections.abc import Callable
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.helpers import DRT, NET, edge, every_route, fleet_body


def assert_problem(r: Any, status: int, needle: str = "") -> None:
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    body = r.json()
    assert body["status"] == status and body["title"] and body["detail"]
    assert needle.lower() in body["detail"].lower(), body["detail"]


@pytest.fixture
def fleet(client: TestClient) -> TestClient:
    client.post("/v1/fleets", json=fleet_body()).raise_for_status()
    return client


def state(client: TestClient) -> tuple[Any, Any]:
    fleet = client.get("/v1/fleets/f1").json()
    events = client.get("/v1/fleets/f1/events", params={"limit": 1000}).json()
    return fleet, events


GOOD = {"edge": "PLACEHOLDER", "offset": 0.0}


@pytest.mark.parametrize(
    ("body", "status", "needle"),
    [
        ({"position": {"edge": "no-such-edge", "offset": 0.0}}, 404, "no-such-edge"),
        ({"position": {"edge": "E0", "offset": -1.0}}, 422, "offset"),
        ({"position": {"edge": "E0", "offset": 1e9}}, 422, "beyond"),
        ({"position": {"x": 1e9, "y": 1e9}}, 422, ""),
        ({"position": {"lon": 500.0, "lat": 0.0}}, 422, "lon"),
        ({"position": {"x": "a", "y": 0}}, 422, ""),
        ({"position": {"edge": "E0", "offset": 0.0}, "requires": ["Z"]}, 422, "'Z'"),
        (
            {"position": {"edge": "E0", "offset": 0.0}, "requires": ["default"] * 4},
            422,
            "requires 4",
        ),
        ({"position": {"edge": "E0"}, "extra": 1}, 422, "extra"),
        ({}, 422, "position"),
    ],
)
def test_bad_targets_change_nothing(
    fleet: TestClient, body: dict[str, Any], status: int, needle: str
) -> None:
    pos = body.get("position")
    if isinstance(pos, dict) and pos.get("edge") == "E0":
        pos["edge"] = edge(0)
    before = state(fleet)
    assert_problem(fleet.post("/v1/fleets/f1/targets", json=body), status, needle)
    assert state(fleet) == before


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_non_finite_numbers(fleet: TestClient, literal: str) -> None:
    before = state(fleet)
    raw = f'{{"position": {{"x": {literal}, "y": 0.0}}}}'
    r = fleet.post(
        "/v1/fleets/f1/targets", content=raw, headers={"content-type": "application/json"}
    )
    assert_problem(r, 422)
    assert state(fleet) == before


def test_unknown_fleet_and_network(client: TestClient) -> None:
    assert_problem(
        client.post("/v1/fleets/nope/targets", json={"position": {"edge": edge(0)}}), 404, "nope"
    )
    assert_problem(client.get("/v1/fleets/nope/metrics"), 404, "nope")
    assert_problem(client.post("/v1/fleets", json=fleet_body(network="atlantis")), 404, "atlantis")
    assert_problem(client.get("/v1/networks/atlantis"), 404, "atlantis")
    assert client.get("/v1/fleets").json()["items"] == []


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        ({"vehicles": []}, "vehicles"),
        ({"cost": "money"}, "cost"),
        ({"objective": 0.5}, "objective"),
        ({"step": {"kind": "inverse", "a": 1.0, "power": 0.3}}, "power"),
        ({"step": {"kind": "inverse", "a": -1.0}}, "a"),
        ({"id": "bad id with spaces"}, "id"),
    ],
)
def test_bad_fleets_are_rejected(client: TestClient, change: dict[str, Any], needle: str) -> None:
    assert_problem(client.post("/v1/fleets", json=fleet_body(**change)), 422, needle)
    assert client.get("/v1/fleets").json()["items"] == []


def test_duplicate_vehicle_ids_and_missing_positions(client: TestClient) -> None:
    body = fleet_body(vehicles=[{"id": "a", "position": {"edge": edge(0)}}] * 2)
    assert_problem(client.post("/v1/fleets", json=body), 422, "unique")
    body = fleet_body(vehicles=[{"id": "a"}])
    assert_problem(client.post("/v1/fleets", json=body), 422, "position")
    placed = {"id": "p", "position": {"edge": edge(0)}}
    body = fleet_body(vehicles=[placed, *({"id": f"u{i}"} for i in range(7))])
    r = client.post("/v1/fleets", json=body)
    assert_problem(r, 422, "7 of 8 vehicles have no position (u0, u1, u2, u3, u4 and 2 more)")
    assert client.get("/v1/fleets").json()["items"] == []


def test_bad_travel_times(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body(cost="time")).raise_for_status()
    before = state(client)
    assert_problem(client.put("/v1/fleets/f1/traveltimes", json={"times": {"zz": 1.0}}), 404, "zz")
    assert_problem(
        client.put("/v1/fleets/f1/traveltimes", json={"times": {edge(0): -1.0}}), 422, ""
    )
    assert state(client) == before


XXE = b"""<?xml version="1.0"?>
<!DOCTYPE net [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>
<net><edge id="&xxe;"/></net>"""

BOMB = b"""<?xml version="1.0"?>
<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
<!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">]>
<net>&lol3;</net>"""


HOSTILE_UPLOADS: dict[str, tuple[Callable[[], bytes], int]] = {
    "empty": (lambda: b"", 422),
    "not-xml": (lambda: b"this is not xml", 422),
    "unclosed": (lambda: b"<net><edge></net>", 422),
    "not-a-net": (lambda: b"<html></html>", 422),
    "xxe": (lambda: XXE, 422),
    "entity-bomb": (lambda: BOMB, 422),
    "deep": (lambda: b"<net>" + b"<a>" * 10000 + b"</a>" * 10000 + b"</net>", 422),
    "gzip-elements": (
        lambda: gzip.compress(b"<net>" + b"<a/>" * (80 * 1024 * 1024) + b"</net>", mtime=0),
        422,
    ),
    "gzip-size": (
        lambda: gzip.compress(
            b"<net>" + (b"<a/>" + b" " * 12) * (5 * 1024 * 1024) + b"</net>", mtime=0
        ),
        413,
    ),
    "too-large": (lambda: b"x" * (70 * 1024 * 1024), 413),
}


@pytest.mark.parametrize("name", list(HOSTILE_UPLOADS))
def test_hostile_network_uploads(client: TestClient, name: str) -> None:
    build, status = HOSTILE_UPLOADS[name]
    assert_problem(client.post("/v1/networks", content=build()), status)
    assert [n["id"] for n in client.get("/v1/networks").json()["items"]] == ["drt"]


def test_network_upload_round_trip(client: TestClient) -> None:
    with open(DRT, "rb") as f:
        data = gzip.compress(f.read())
    r = client.post("/v1/networks", params={"name": "drt2"}, content=data)
    assert r.status_code == 201, r.text
    assert r.json()["edges"] == NET.n_edges
    assert client.get("/v1/networks/drt2").json()["sha256"] == r.json()["sha256"]


def test_oversized_json_body(client: TestClient) -> None:
    big = {"targets": [{"position": {"edge": "x" * 200, "offset": 0.0}}] * 40000}
    assert_problem(client.post("/v1/fleets/f1/targets:batch", json=big), 413)


def test_api_key_guards_every_write_route(db_url: str, make_client: Any) -> None:
    c = make_client(db_url, api_key="s3cret")
    routes = every_route(c.app.routes)
    writes = [(m, p) for m, p in routes if m not in {"GET", "HEAD", "OPTIONS"}]
    assert len(writes) >= 7, routes
    for method, path in writes:
        url = path.replace("{fleet_id}", "f1").replace("{network_id}", "drt")
        r = c.request(method, url, json={})
        assert_problem(r, 401, "X-API-Key")
    r = c.post("/v1/fleets", json=fleet_body(), headers={"X-API-Key": "s3cret"})
    assert r.status_code == 201
    assert c.get("/v1/fleets/f1").status_code == 200
