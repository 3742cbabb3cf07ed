"""Vehicle state and dispatch through HTTP, on SQLite and PostgreSQL.

The dispatch answer is checked against a brute force over the vehicles with
scipy's full Dijkstra (:meth:`RoadSpace.cost_matrix`), independent of the
early-exit search that serves the targets.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import sqlalchemy as sa
from fastapi.testclient import TestClient

from routing_svc.network import RoadSpace, load_network
from routing_svc.store.schema import events, fleets
from routing_svc.types import NetPosition
from tests.helpers import DRT

NET = load_network(DRT)
SPACE = RoadSpace(NET, cost="length")
PROBLEM = "application/problem+json"
EDGES = (0, 40, 100, 160, 220, 300)


def edge(i: int) -> str:
    return NET.edge_ids[i]


def fleet_body(fleet_id: str = "f1", **extra: Any) -> dict[str, Any]:
    body: dict[str, Any] = {
        "id": fleet_id,
        "network": "drt",
        "rule": "paper",
        "vehicles": [
            {"id": f"v{k}", "position": {"edge": edge(e), "offset": 1.0}}
            for k, e in enumerate(EDGES)
        ],
    }
    body.update(extra)
    return body


def position(described: dict[str, Any]) -> NetPosition:
    return NetPosition(NET.edge_index[described["edge"]], float(described["offset"]))


def random_targets(rng: np.random.Generator, n: int) -> list[dict[str, Any]]:
    edges = rng.integers(0, len(NET.edge_ids), n)
    return [
        {"edge": edge(int(e)), "offset": float(rng.uniform(0.0, NET.length[int(e)]))} for e in edges
    ]


def closest(
    vehicles: list[dict[str, Any]], target: dict[str, Any], where: str
) -> tuple[str, float]:
    """Brute force: the vehicle whose ``where`` position is closest (ties by id)."""
    costs = SPACE.cost_matrix([position(v[where]) for v in vehicles], [position(target)])[:, 0]
    best = min(range(len(vehicles)), key=lambda i: (costs[i], vehicles[i]["id"]))
    return vehicles[best]["id"], float(costs[best])


def put_state(client: TestClient, vid: str, body: dict[str, Any], **headers: str) -> Any:
    return client.put(f"/v1/fleets/f1/vehicles/{vid}/state", json=body, headers=headers)


def test_get_shows_status_current_position_and_reference(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body()).raise_for_status()
    fresh = client.get("/v1/fleets/f1").json()
    for v in fresh["vehicles"]:
        assert v["status"] == "available"
        assert v["current"] == v["reference"] == v["position"]
    moved_to = {"edge": edge(50), "offset": 2.0}
    r = put_state(client, "v1", {"status": "busy", "position": moved_to, "timestamp": 100.0})
    assert r.status_code == 200, r.text
    assert r.json()["version"] == 2
    (shown,) = r.json()["vehicles"]
    assert (shown["status"], shown["current"]["edge"], shown["timestamp"]) == (
        "busy",
        edge(50),
        100.0,
    )
    v1 = client.get("/v1/fleets/f1").json()["vehicles"][1]
    assert v1["status"] == "busy" and v1["current"]["edge"] == edge(50)
    assert v1["reference"] == fresh["vehicles"][1]["reference"]
    # without a position the vehicle stays where it is; null puts it back at its reference
    put_state(client, "v1", {"status": "available"}).raise_for_status()
    assert client.get("/v1/fleets/f1").json()["vehicles"][1]["current"]["edge"] == edge(50)
    put_state(client, "v1", {"status": "offline", "position": None}).raise_for_status()
    v1 = client.get("/v1/fleets/f1").json()["vehicles"][1]
    assert v1["status"] == "offline" and v1["current"] == v1["reference"]
    assert v1["timestamp"] == 100.0  # kept


def test_dispatch_picks_the_closest_available_by_current_position(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body()).raise_for_status()
    changes = [
        {"vehicle": "v0", "status": "busy"},
        {"vehicle": "v2", "status": "offline"},
        {"vehicle": "v3", "status": "available", "position": {"edge": edge(500), "offset": 0.5}},
        {"vehicle": "v4", "status": "available", "position": {"edge": edge(20), "offset": 3.0}},
    ]
    client.post("/v1/fleets/f1/vehicles/state:batch", json={"changes": changes}).raise_for_status()
    rng = np.random.default_rng(3)
    for target in random_targets(rng, 15):
        fleet = client.get("/v1/fleets/f1").json()
        vehicles = fleet["vehicles"]
        available = [v for v in vehicles if v["status"] == "available"]
        want_sent, want_cost = closest(available, target, "current")
        want_moved, _ = closest(vehicles, target, "reference")  # the paper's rule
        asked = client.post("/v1/fleets/f1/assign", json={"position": target}).json()
        served = client.post("/v1/fleets/f1/targets", json={"position": target}).json()
        for answer in (asked, served):
            dispatch = answer["dispatch"]
            assert dispatch["status"] == "dispatched" and dispatch["missing"] == []
            assert [s["vehicle"] for s in dispatch["vehicles"]] == [want_sent]
            assert math.isclose(dispatch["cost"], want_cost, rel_tol=1e-9, abs_tol=1e-9)
            assert answer["moved"] == want_moved
        assert client.get("/v1/fleets/f1").json()["version"] == fleet["version"] + 1


def test_queued_and_partial_answers(client: TestClient) -> None:
    vehicles = [
        {"id": "a1", "type": "A", "position": {"edge": edge(0), "offset": 0.0}},
        {"id": "a2", "type": "A", "position": {"edge": edge(100), "offset": 0.0}},
        {"id": "b1", "type": "B", "position": {"edge": edge(200), "offset": 0.0}},
    ]
    client.post("/v1/fleets", json=fleet_body(vehicles=vehicles, rule="probe")).raise_for_status()
    busy = [{"vehicle": v, "status": "busy"} for v in ("a1", "a2")]
    client.put("/v1/fleets/f1/vehicles/state", json={"changes": busy}).raise_for_status()
    target = {"position": {"edge": edge(60), "offset": 1.0}, "requires": ["A", "B"]}
    partial = client.post("/v1/fleets/f1/targets", json=target).json()
    assert partial["dispatch"]["status"] == "partial"
    assert partial["dispatch"]["missing"] == ["A"] and partial["dispatch"]["cost"] is None
    assert [(s["vehicle"], s["type"]) for s in partial["dispatch"]["vehicles"]] == [("b1", "B")]
    assert partial["moved"] in {"a1", "a2", "b1"}  # learning still uses the references
    put_state(client, "b1", {"status": "offline"}).raise_for_status()
    queued = client.post("/v1/fleets/f1/targets", json=target).json()["dispatch"]
    assert queued == {"status": "queued", "vehicles": [], "missing": ["A", "B"], "cost": None}
    anyone = client.post("/v1/fleets/f1/targets", json={"position": target["position"]}).json()
    assert anyone["dispatch"]["missing"] == ["*"]
    levels = client.get("/v1/fleets/f1/metrics").json()["service_levels"]
    assert levels["all"]["targets"] == 3 and levels["all"]["undispatched"] == 3
    assert levels["all"]["within"] == [0.0, 0.0, 0.0]


def test_the_availability_aware_rule_moves_the_closest_available_reference(
    client: TestClient,
) -> None:
    target = {"edge": edge(101), "offset": 0.5}
    for name, learning in (("every", "all"), ("free", "available")):
        body = fleet_body(name, learning_vehicles=learning)
        assert client.post("/v1/fleets", json=body).json()["learning_vehicles"] == learning
    vehicles = client.get("/v1/fleets/every").json()["vehicles"]
    first, _ = closest(vehicles, target, "reference")
    second, _ = closest([v for v in vehicles if v["id"] != first], target, "reference")
    assert first != second
    for name in ("every", "free"):
        url = f"/v1/fleets/{name}/vehicles/{first}/state"
        client.put(url, json={"status": "busy"}).raise_for_status()
    every = client.post("/v1/fleets/every/targets", json={"position": target}).json()
    free = client.post("/v1/fleets/free/targets", json={"position": target}).json()
    assert every["moved"] == first  # the paper's rule: busy or not
    assert free["moved"] == second  # the closest available reference
    assert every["dispatch"]["vehicles"][0]["vehicle"] == second
    assert free["dispatch"]["vehicles"][0]["vehicle"] == second
    # the consolidating rule composes: the held step acts on the available mover's reference
    body = fleet_body("held", learning_vehicles="available", rule="consolidating")
    client.post("/v1/fleets", json=body).raise_for_status()
    client.put(f"/v1/fleets/held/vehicles/{first}/state", json={"status": "busy"})
    held = client.post("/v1/fleets/held/targets", json={"position": target}).json()
    assert held["moved"] == second


def state_of(client: TestClient) -> tuple[int, list[dict[str, Any]]]:
    fleet = client.get("/v1/fleets/f1").json()
    return fleet["version"], fleet["vehicles"]


def test_bad_input_is_a_problem_and_changes_nothing(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body()).raise_for_status()
    put_state(client, "v1", {"status": "busy", "timestamp": 50.0}).raise_for_status()
    before = state_of(client)
    cases: list[tuple[str, dict[str, Any], int]] = [
        ("v9", {"status": "busy"}, 404),  # unknown vehicle
        ("v1", {"status": "flying"}, 422),  # not one of the three
        ("v1", {"status": "busy", "position": {"x": 1e7, "y": 1e7}}, 422),  # off the network
        ("v1", {"status": "busy", "position": {"edge": "nowhere"}}, 404),  # unknown edge
        ("v1", {"status": "available", "timestamp": 49.0}, 409),  # back in time
        ("v1", {"status": "busy", "timestamp": "2020-01-01T00:00:00"}, 422),  # no time zone
    ]
    for vid, body, status in cases:
        r = put_state(client, vid, body)
        assert r.status_code == status, (body, r.text)
        assert r.headers["content-type"].startswith(PROBLEM)
        assert state_of(client) == before
    # a batch is all or none: one bad change fails the whole batch
    batch = {
        "changes": [
            {"vehicle": "v2", "status": "busy"},
            {"vehicle": "v1", "status": "busy", "timestamp": 10.0},
        ]
    }
    r = client.post("/v1/fleets/f1/vehicles/state:batch", json=batch)
    assert r.status_code == 409 and r.headers["content-type"].startswith(PROBLEM)
    assert state_of(client) == before
    r = client.put("/v1/fleets/nope/vehicles/v1/state", json={"status": "busy"})
    assert r.status_code == 404
    # an ISO time with a zone is accepted, and later than 50 s
    ok = put_state(client, "v1", {"status": "available", "timestamp": "2020-01-01T00:00:00Z"})
    assert ok.status_code == 200 and ok.json()["vehicles"][0]["timestamp"] == 1577836800.0


def test_idempotent_retries_apply_once(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body()).raise_for_status()
    body = {"status": "busy", "position": {"edge": edge(7), "offset": 0.0}}
    first = put_state(client, "v1", body, **{"Idempotency-Key": "s1"})
    again = put_state(client, "v1", body, **{"Idempotency-Key": "s1"})
    assert first.status_code == again.status_code == 200
    assert first.json() == again.json()
    assert client.get("/v1/fleets/f1").json()["version"] == 2
    clash = put_state(client, "v1", {"status": "offline"}, **{"Idempotency-Key": "s1"})
    assert clash.status_code == 409
    events = client.get("/v1/fleets/f1/events").json()["items"]
    assert [e["kind"] for e in events] == ["fleet_created", "vehicle_state"]


def test_service_levels_follow_the_dispatched_costs(client: TestClient) -> None:
    thresholds = [40.0, 120.0, 400.0]
    client.post("/v1/fleets", json=fleet_body(service_thresholds=thresholds)).raise_for_status()
    put_state(client, "v0", {"status": "busy"}).raise_for_status()
    rng = np.random.default_rng(5)
    costs = []
    for target in random_targets(rng, 30):
        costs.append(client.post("/v1/fleets/f1/targets", json={"position": target}).json())
    completion = np.array([c["dispatch"]["cost"] for c in costs])
    levels = client.get("/v1/fleets/f1/metrics").json()["service_levels"]
    assert levels["thresholds"] == thresholds
    for scope in ("all", "recent"):
        assert levels[scope]["within"] == [float(np.mean(completion <= t)) for t in thresholds]
    exact = {p: float(np.percentile(completion, p, method="inverted_cdf")) for p in (50, 90, 95)}
    for p, value in exact.items():
        assert levels["recent"]["percentiles"][f"p{p}"] == value
        assert value <= levels["all"]["percentiles"][f"p{p}"] <= value * 1.01
    bad = client.post("/v1/fleets", json=fleet_body("bad", service_thresholds=[600, 300]))
    assert bad.status_code == 422


def test_replay_after_restart_gives_the_same_state(db_url: str, make_client: Any) -> None:
    first = make_client(db_url)
    first.post("/v1/fleets", json=fleet_body()).raise_for_status()
    rng = np.random.default_rng(11)
    for k, target in enumerate(random_targets(rng, 70)):  # past a snapshot (every 64)
        if k % 10 == 0:
            vid = f"v{k % len(EDGES)}"
            status = ("busy", "available", "offline")[k % 3]
            where = random_targets(rng, 1)[0]
            body = {"status": status, "position": where, "timestamp": float(k)}
            put_state(first, vid, body).raise_for_status()
        first.post("/v1/fleets/f1/targets", json={"position": target}).raise_for_status()
    fleet, metrics = first.get("/v1/fleets/f1").json(), first.get("/v1/fleets/f1/metrics").json()
    first.__exit__(None, None, None)
    again = make_client(db_url)
    assert again.get("/v1/fleets/f1").json() == fleet
    assert again.get("/v1/fleets/f1/metrics").json() == metrics
    checked = again.app.state.fleets.verify("f1")
    assert checked["snapshot_identical"] is True and checked["version"] == fleet["version"]


def test_a_log_written_before_vehicle_states_replays_to_the_same_bytes(
    db_url: str, make_client: Any
) -> None:
    """A database from before this change: target results without ``dispatch``, a
    snapshot without service levels. It replays exactly, and the service levels are
    derived from its log."""
    first = make_client(db_url)
    first.post("/v1/fleets", json=fleet_body()).raise_for_status()
    rng = np.random.default_rng(12)
    for target in random_targets(rng, 70):
        first.post("/v1/fleets/f1/targets", json={"position": target}).raise_for_status()
    metrics = first.get("/v1/fleets/f1/metrics").json()
    first.__exit__(None, None, None)
    engine = sa.create_engine(db_url)
    with engine.begin() as conn:
        rows = conn.execute(sa.select(events.c.seq, events.c.result)).all()
        for seq, result in rows:
            data = json.loads(result or "{}")
            if data.pop("dispatch", None) is not None:
                old = json.dumps(data, separators=(",", ":"), sort_keys=True)
                conn.execute(events.update().where(events.c.seq == seq).values(result=old))
        (state,) = conn.execute(sa.select(fleets.c.state)).one()
        snapshot = json.loads(state)
        del snapshot["service_levels"]
        old = json.dumps(snapshot, separators=(",", ":"), sort_keys=True)
        conn.execute(fleets.update().values(state=old))
    engine.dispose()
    again = make_client(db_url)
    assert again.app.state.fleets.verify("f1")["snapshot_identical"] is True
    assert again.get("/v1/fleets/f1/metrics").json() == metrics
    target = {"position": random_targets(rng, 1)[0]}
    assert "dispatch" in again.post("/v1/fleets/f1/targets", json=target).json()


def test_prometheus_shows_the_service_levels(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body("prom", service_thresholds=[50.0, 5000.0]))
    rng = np.random.default_rng(8)
    for target in random_targets(rng, 5):
        client.post("/v1/fleets/prom/targets", json={"position": target}).raise_for_status()
    levels = client.get("/v1/fleets/prom/metrics").json()["service_levels"]
    text = client.get("/metrics").text
    for limit, fraction in zip([50.0, 5000.0], levels["all"]["within"], strict=True):
        line = f'routing_svc_fleet_within_threshold{{fleet="prom",scope="all",threshold="{limit}"}}'
        assert f"{line} {fraction}" in text
    p90 = levels["recent"]["percentiles"]["p90"]
    assert (
        f'routing_svc_fleet_completion_cost{{fleet="prom",quantile="0.9",scope="recent"}} {p90}'
        in text
    )
