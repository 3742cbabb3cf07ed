"""The REST API through HTTP semantics (FastAPI's TestClient), on SQLite and PostgreSQL."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from routing_svc.network import RoadSpace
from routing_svc.offline_run import network_scenario, starting_positions
from routing_svc.types import NetPosition
from tests.helpers import DRT, NET, edge, fleet_body

SPACE = RoadSpace(NET, cost="length")


def test_full_life_of_a_fleet(client: TestClient) -> None:
    nets = client.get("/v1/networks").json()["items"]
    assert [n["id"] for n in nets] == ["drt"]
    assert nets[0]["edges"] == NET.n_edges and nets[0]["has_projection"] is True
    geo = client.get("/v1/networks/drt/geometry").json()
    assert geo["type"] == "FeatureCollection" and len(geo["features"]) == NET.n_edges

    r = client.post("/v1/fleets", json=fleet_body())
    assert r.status_code == 201, r.text
    fleet = r.json()
    assert fleet["version"] == 1 and fleet["targets"] == 0
    assert [v["id"] for v in fleet["vehicles"]] == ["v1", "v2", "v3"]
    v1 = fleet["vehicles"][0]["position"]
    assert v1["edge"] == edge(0) and v1["offset"] == 1.0
    assert {"x", "y", "lon", "lat"} <= set(v1)

    rng = np.random.default_rng(0)
    for k in range(20):
        e = int(rng.integers(NET.n_edges))
        target = {"edge": edge(e), "offset": float(NET.length[e]) / 2}
        before = client.post("/v1/fleets/f1/assign", json={"position": target}).json()
        r = client.post("/v1/fleets/f1/targets", json={"position": target})
        assert r.status_code == 200, r.text
        out = r.json()
        assert out["seq"] == k + 2 and out["version"] == k + 2
        assert out["served_by"] == before["served_by"] and out["moved"] == before["moved"]
        assert out["cost"] == pytest.approx(before["cost"])
        # the service cost is the shortest-path cost from the mover's old position
        # (independent check: scipy's Dijkstra over the same graph)
        old = {v["id"]: v for v in fleet["vehicles"]}[out["moved"]]["position"]
        old_pos = NetPosition(NET.edge_index[old["edge"]], old["offset"])
        tgt_pos = NetPosition(e, float(NET.length[e]) / 2)
        assert out["cost"] == pytest.approx(SPACE.cost_matrix([old_pos], [tgt_pos])[0, 0])
        fleet = client.get("/v1/fleets/f1").json()
        moved = {v["id"]: v for v in fleet["vehicles"]}[out["moved"]]
        assert moved["position"] == out["new_position"]

    assert fleet["version"] == 21 and fleet["targets"] == 20
    page = client.get("/v1/fleets/f1/events", params={"after": 0, "limit": 5}).json()
    assert [e["seq"] for e in page["items"]] == [1, 2, 3, 4, 5]
    assert page["items"][0]["kind"] == "fleet_created"
    page2 = client.get("/v1/fleets/f1/events", params={"after": page["next_after"]}).json()
    assert page2["items"][0]["seq"] == 6 and page2["items"][-1]["seq"] == 21

    m = client.get("/v1/fleets/f1/metrics").json()
    assert m["targets"] == 20 and sum(m["updates"].values()) == 20
    assert m["mean_cost"] > 0 and m["optimum"] is None
    assert set(m["step_size"]) == {"v1", "v2", "v3"}

    assert client.get("/v1/fleets").json()["items"][0]["id"] == "f1"
    assert client.delete("/v1/fleets/f1").status_code == 204
    r = client.get("/v1/fleets/f1")
    assert r.status_code == 404
    assert r.headers["content-type"].startswith("application/problem+json")
    assert client.post("/v1/fleets", json=fleet_body()).status_code == 409  # ids are not reused


def test_positions_given_as_xy_and_lonlat_are_snapped(client: TestClient) -> None:
    x, y = SPACE.xy(NetPosition(42, 3.0))
    lon, lat = SPACE.lonlat(NetPosition(42, 3.0))
    body = fleet_body(
        vehicles=[
            {"id": "a", "position": {"x": x, "y": y}},
            {"id": "b", "position": {"lon": lon, "lat": lat}},
        ]
    )
    fleet = client.post("/v1/fleets", json=body).json()
    for v in fleet["vehicles"]:
        assert (
            v["position"]["edge"] == edge(42)
            or np.hypot(v["position"]["x"] - x, v["position"]["y"] - y) < 0.5
        )
        assert v["position"]["offset"] == pytest.approx(3.0, abs=0.5)


def test_heterogeneous_a_b_ab_fleet(client: TestClient) -> None:
    positions = [0, 60, 120, 180, 240, 300]
    vehicles = [
        {"id": f"{t.lower()}{i}", "type": t, "speed": 1.0 + (i % 2),
         "position": {"edge": edge(positions[i + 3 * (t == "B")]), "offset": 0.0}}
        for t in ("A", "B") for i in range(3)
    ]  # fmt: skip
    client.post("/v1/fleets", json=fleet_body(vehicles=vehicles)).raise_for_status()
    rng = np.random.default_rng(3)
    for k in range(30):
        e = int(rng.integers(NET.n_edges))
        target = {"edge": edge(e), "offset": 0.0}
        requires = [["A"], ["B"], ["A", "B"]][k % 3]
        fleet = client.get("/v1/fleets/f1").json()
        out = client.post("/v1/fleets/f1/targets", json={"position": target, "requires": requires})
        assert out.status_code == 200, out.text
        res = out.json()
        # independent reference: the full cost matrix (scipy Dijkstra), divided by speeds
        vs = fleet["vehicles"]
        pos = [
            NetPosition(NET.edge_index[v["position"]["edge"]], v["position"]["offset"]) for v in vs
        ]
        times = SPACE.cost_matrix(pos, [NetPosition(e, 0.0)])[:, 0] / [v["speed"] for v in vs]
        expected = []
        for t in sorted(requires):
            idx = [i for i, v in enumerate(vs) if v["type"] == t]
            best = min(idx, key=lambda i: (times[i], vs[i]["id"]))
            expected.append(best)
        assert res["served_by"] == [vs[i]["id"] for i in expected]
        last = max(expected, key=lambda i: (times[i], [-ord(c) for c in vs[i]["id"]]))
        assert res["moved"] == vs[last]["id"]
        assert res["cost"] == pytest.approx(times[last])
        if requires == ["A", "B"]:
            types = {v["id"]: v["type"] for v in vs}
            assert sorted(types[i] for i in res["served_by"]) == ["A", "B"]


def test_idempotent_retries(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body()).raise_for_status()
    body = {"position": {"edge": edge(7), "offset": 0.0}}
    first = client.post("/v1/fleets/f1/targets", json=body, headers={"Idempotency-Key": "k1"})
    again = client.post("/v1/fleets/f1/targets", json=body, headers={"Idempotency-Key": "k1"})
    assert first.status_code == again.status_code == 200
    assert first.content == again.content
    assert client.get("/v1/fleets/f1").json()["version"] == 2
    other = {"position": {"edge": edge(8), "offset": 0.0}}
    clash = client.post("/v1/fleets/f1/targets", json=other, headers={"Idempotency-Key": "k1"})
    assert clash.status_code == 409
    assert client.get("/v1/fleets/f1").json()["version"] == 2

    batch = {"targets": [body, other, body]}
    b1 = client.post("/v1/fleets/f1/targets:batch", json=batch, headers={"Idempotency-Key": "b"})
    b2 = client.post("/v1/fleets/f1/targets:batch", json=batch, headers={"Idempotency-Key": "b"})
    assert b1.status_code == 200 and b1.content == b2.content
    assert [r["seq"] for r in b1.json()["results"]] == [3, 4, 5]
    assert client.get("/v1/fleets/f1").json()["version"] == 5


def test_batch_equals_single_posts(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body("one")).raise_for_status()
    client.post("/v1/fleets", json=fleet_body("many")).raise_for_status()
    rng = np.random.default_rng(9)
    targets = [
        {"position": {"edge": edge(int(e)), "offset": 0.0}}
        for e in rng.integers(NET.n_edges, size=25)
    ]
    singles = [client.post("/v1/fleets/one/targets", json=t).json() for t in targets]
    batch = client.post("/v1/fleets/many/targets:batch", json={"targets": targets}).json()
    assert [s["new_position"] for s in singles] == [b["new_position"] for b in batch["results"]]
    one = client.get("/v1/fleets/one").json()["vehicles"]
    many = client.get("/v1/fleets/many").json()["vehicles"]
    assert one == many


def test_time_costs_and_travel_times(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body(cost="time")).raise_for_status()
    target = {"position": {"edge": edge(5), "offset": 0.0}}
    before = client.post("/v1/fleets/f1/assign", json=target).json()
    slow = {edge(i): 1e5 for i in range(NET.n_edges) if i != 5}
    r = client.put("/v1/fleets/f1/traveltimes", json={"times": slow})
    assert r.status_code == 200, r.text
    assert r.json()["version"] == 2
    after = client.post("/v1/fleets/f1/assign", json=target).json()
    assert after["cost"] > before["cost"] + 1e4
    length_fleet = fleet_body("len")
    client.post("/v1/fleets", json=length_fleet).raise_for_status()
    assert (
        client.put("/v1/fleets/len/traveltimes", json={"times": {edge(1): 3.0}}).status_code == 409
    )


def test_reference_demand_gives_a_gap(client: TestClient) -> None:
    body = fleet_body(reference_demand={"kind": "hotspots", "count": 2, "seed": 4})
    client.post("/v1/fleets", json=body).raise_for_status()
    m = client.get("/v1/fleets/f1/metrics").json()
    opt = m["optimum"]
    assert opt is not None and opt["objective"] > 0
    assert opt["expected_cost"] >= opt["objective"] * (1 - 1e-9)
    assert opt["gap"] == pytest.approx((opt["expected_cost"] - opt["objective"]) / opt["objective"])


def test_a_reference_optimum_of_zero_gives_no_finite_gap(client: TestClient) -> None:
    # SUMO's Ingolstadt game network keeps four edges: eight vehicles can stand on every
    # atom of this demand, and the fleet made to start elsewhere is not there yet
    net = Path(__import__("sumo").SUMO_HOME) / "tools/game/fkk_in/ingolstadt.net.xml.gz"
    client.post("/v1/networks?name=ing", content=net.read_bytes()).raise_for_status()
    ids = ["-148050455#0", "148050455#0", "-306431310#1", "306431310#1"]
    vehicles = [{"id": f"v{i}", "position": {"edge": ids[i % 4], "offset": 0.0}} for i in range(8)]
    demand = {"kind": "hotspots", "count": 3, "spread": 50.0, "seed": 1}
    body = {"id": "ing", "network": "ing", "vehicles": vehicles, "reference_demand": demand}
    client.post("/v1/fleets", json=body).raise_for_status()
    opt = client.get("/v1/fleets/ing/metrics").json()["optimum"]
    assert opt["objective"] == 0.0 and opt["proven_optimal"]
    assert opt["expected_cost"] > 0.0 and opt["gap"] is None


def test_start_at_the_optimum_of_a_prior_sample(client: TestClient) -> None:
    sample = [{"edge": edge(10), "offset": 0.0}] * 5 + [{"edge": edge(400), "offset": 0.0}] * 5
    body = fleet_body(
        vehicles=[{"id": "a"}, {"id": "b"}],
        start={"optimum": {"sample": sample}},
    )
    r = client.post("/v1/fleets", json=body)
    assert r.status_code == 201, r.text
    edges = sorted(v["position"]["edge"] for v in r.json()["vehicles"])
    # two vehicles for two demand points: each sits on one (cost 0)
    assert edges == sorted([edge(10), edge(400)])


def test_each_type_starts_at_the_optimum_of_the_whole_sample(client: TestClient) -> None:
    sample: list[dict[str, Any]] = [{"edge": edge(10), "offset": 0.0}] * 6
    sample += [{"edge": edge(400), "offset": 0.0}] * 4
    vehicles = [{"id": "a1", "type": "A"}, {"id": "a2", "type": "A"}, {"id": "b1", "type": "B"}]
    vehicles += [{"id": "b2", "type": "B"}, {"id": "b3", "type": "B"}]
    body = fleet_body(vehicles=vehicles, start={"optimum": {"sample": sample}})
    r = client.post("/v1/fleets", json=body)
    assert r.status_code == 201, r.text
    fleet = r.json()
    assert fleet["rule"] == "consolidating"
    at = {v["id"]: v["position"] for v in fleet["vehicles"]}
    # the sample names no types: each type covers both demand points (cost 0 for its
    # targets); a p-median of all five vehicles may leave one type on one point only
    assert {at["a1"]["edge"], at["a2"]["edge"]} == {edge(10), edge(400)}
    assert {at[b]["edge"] for b in ("b1", "b2", "b3")} >= {edge(10), edge(400)}
    # each type counts the whole sample in its step sizes: per type, every target goes
    # to the closest vehicle of that type (ties: lower id)
    steps = client.get("/v1/fleets/f1/metrics").json()["step_size"]
    for kind in ("A", "B"):
        _steps_match_counts(steps, fleet, sorted(v for v in at if v[0] == kind.lower()), sample)


def _steps_match_counts(
    steps: dict[str, float], fleet: dict[str, Any], ids: list[str], own: list[dict[str, Any]]
) -> None:
    """Each of ``ids`` (one type) has the step size of the targets of ``own`` it reaches
    first among them (ties: lower id)."""
    at = {v["id"]: v["position"] for v in fleet["vehicles"]}
    a, power = fleet["step"]["a"], fleet["step"]["power"]
    points = [NetPosition(NET.edge_index[t["edge"]], t["offset"]) for t in own]
    starts = [NetPosition(NET.edge_index[at[v]["edge"]], at[v]["offset"]) for v in ids]
    counts = np.bincount(SPACE.cost_matrix(starts, points).argmin(axis=0), minlength=len(ids))
    assert counts.sum() == len(own)
    for v, k in zip(ids, counts, strict=True):
        assert steps[v] == pytest.approx(a / (k + 1) ** power)


def _two_a_and_one_b_at_the_optimum_of(
    client: TestClient, sample: list[dict[str, Any]], requires: list[Any]
) -> dict[str, Any]:
    """Create ``f1``, vehicles a1, a2 (type A) and b1 (B), at the optimum of ``sample``."""
    vehicles = [{"id": "a1", "type": "A"}, {"id": "a2", "type": "A"}, {"id": "b1", "type": "B"}]
    body = fleet_body(
        vehicles=vehicles, start={"optimum": {"sample": sample, "requires": requires}}
    )
    r = client.post("/v1/fleets", json=body)
    assert r.status_code == 201, r.text
    fleet: dict[str, Any] = r.json()
    return fleet


def test_each_type_starts_at_the_optimum_of_the_sample_targets_that_needed_it(
    client: TestClient,
) -> None:
    a_targets: list[dict[str, Any]] = [{"edge": edge(10), "offset": 0.0}] * 6
    a_targets += [{"edge": edge(200), "offset": 0.0}] * 2
    b_targets: list[dict[str, Any]] = [{"edge": edge(400), "offset": 0.0}] * 4
    sample = a_targets + b_targets
    requires: list[Any] = [["A"]] * len(a_targets) + [["B"]] * len(b_targets)
    fleet = _two_a_and_one_b_at_the_optimum_of(client, sample, requires)
    at = {v["id"]: v["position"] for v in fleet["vehicles"]}
    # each type on the points of its own targets (cost 0 for every target); from the
    # whole sample, the one B would stand at the 1-median of all twelve
    assert {at["a1"]["edge"], at["a2"]["edge"]} == {edge(10), edge(200)}
    assert (at["b1"]["edge"], at["b1"]["offset"]) == (edge(400), 0.0)
    steps = client.get("/v1/fleets/f1/metrics").json()["step_size"]
    _steps_match_counts(steps, fleet, ["a1", "a2"], a_targets)
    _steps_match_counts(steps, fleet, ["b1"], b_targets)


def test_targets_for_any_vehicle_count_for_every_type_of_an_optimum_start(
    client: TestClient,
) -> None:
    a_targets: list[dict[str, Any]] = [{"edge": edge(10), "offset": 0.0}] * 6
    b_targets: list[dict[str, Any]] = [{"edge": edge(400), "offset": 0.0}] * 4
    anyone: list[dict[str, Any]] = [{"edge": edge(300), "offset": 0.0}] * 3
    sample = a_targets + b_targets + anyone
    requires: list[Any] = [["A"]] * 6 + [["B"]] * 4 + [None, [], None]
    fleet = _two_a_and_one_b_at_the_optimum_of(client, sample, requires)
    at = {v["id"]: v["position"] for v in fleet["vehicles"]}
    assert {at["a1"]["edge"], at["a2"]["edge"]} == {edge(10), edge(300)}
    # the three for anyone count for both types: A on them and its own; the one B then
    # fits the rest, its own targets (the 1-median of its targets and the three for
    # anyone, against every edge's start and every target point: here the same place)
    own = b_targets + anyone
    points = [NetPosition(NET.edge_index[t["edge"]], 0.0) for t in own]
    candidates = [NetPosition(e, 0.0) for e in range(NET.n_edges)]
    best = float(SPACE.cost_matrix(candidates, points).sum(axis=1).min())
    b1 = NetPosition(NET.edge_index[at["b1"]["edge"]], at["b1"]["offset"])
    assert float(SPACE.cost_matrix([b1], points).sum()) == pytest.approx(best, rel=1e-9)
    steps = client.get("/v1/fleets/f1/metrics").json()["step_size"]
    _steps_match_counts(steps, fleet, ["a1", "a2"], a_targets + anyone)
    _steps_match_counts(steps, fleet, ["b1"], own)


def test_types_of_a_sample_for_any_vehicle_start_on_different_places(
    client: TestClient,
) -> None:
    places = [edge(10), edge(200), edge(400)]
    sample: list[dict[str, Any]] = [{"edge": e, "offset": 0.0} for e in places for _ in range(4)]
    # every target for any one vehicle: objective (11) is the 3-median of all three
    # vehicles, 0 with one on each place; each type at the p-median of the whole sample
    # would put the one B on a place of the two A's
    fleet = _two_a_and_one_b_at_the_optimum_of(client, sample, [None] * len(sample))
    at = {v["id"]: (v["position"]["edge"], v["position"]["offset"]) for v in fleet["vehicles"]}
    assert sorted(at.values()) == sorted((e, 0.0) for e in places)
    # a sample of one target for anyone: every vehicle on it (nothing to refit)
    one = client.post(
        "/v1/fleets",
        json=fleet_body(
            "one",
            vehicles=[{"id": "a1", "type": "A"}, {"id": "b1", "type": "B"}],
            start={"optimum": {"sample": sample[:1], "requires": [None]}},
        ),
    )
    assert one.status_code == 201, one.text
    assert {(v["position"]["edge"], v["position"]["offset"]) for v in one.json()["vehicles"]} == {
        (places[0], 0.0)
    }


@pytest.mark.parametrize(
    ("requires", "detail"),
    [
        ([["A"]], "one entry per sample position"),
        ([["A"], ["C"]], "requires[1]"),
        ([["A", "A", "A"], None], "requires[0]"),
        ([["A"], [""]], "start.optimum.requires.1.0"),
    ],
)
def test_bad_requirements_of_an_optimum_start_change_nothing(
    client: TestClient, requires: list[list[str] | None], detail: str
) -> None:
    sample = [{"edge": edge(10), "offset": 0.0}, {"edge": edge(400), "offset": 0.0}]
    vehicles = [{"id": "a1", "type": "A"}, {"id": "a2", "type": "A"}, {"id": "b1", "type": "B"}]
    body = fleet_body(
        vehicles=vehicles, start={"optimum": {"sample": sample, "requires": requires}}
    )
    r = client.post("/v1/fleets", json=body)
    assert r.status_code == 422, r.text
    assert r.headers["content-type"] == "application/problem+json"
    assert detail in r.text
    assert client.get("/v1/fleets/f1").status_code == 404
    assert client.get("/v1/fleets").json()["items"] == []


def test_a_network_uploaded_through_one_instance_serves_another(
    db_url: str, make_client: Any
) -> None:
    first = make_client(db_url)
    second = make_client(db_url)  # same database and --data-dir, like two instances on one host
    with open(DRT, "rb") as f:
        r = first.post("/v1/networks", params={"name": "town"}, content=f.read())
    assert r.status_code == 201, r.text
    assert second.get("/v1/networks/town").json()["sha256"] == r.json()["sha256"]
    created = second.post("/v1/fleets", json=fleet_body(network="town"))
    assert created.status_code == 201, created.text
    assert first.get("/v1/fleets/f1").json()["network"] == "town"


def test_the_rule_is_consolidating_by_default_and_a_probe_window_keeps_the_probe_rule(
    client: TestClient,
) -> None:
    radius = SPACE.typical_cost() / np.sqrt(3)
    default = client.post("/v1/fleets", json=fleet_body("on")).json()
    assert default["rule"] == "consolidating" and default["probe"] is None
    assert default["step"]["a"] == pytest.approx(0.01 * radius)
    probe = client.post("/v1/fleets", json=fleet_body("probe", rule="probe")).json()
    assert probe["rule"] == "probe" and probe["probe"] == pytest.approx(0.05 * radius)
    wider = client.post("/v1/fleets", json=fleet_body("wide", probe=0.2)).json()
    assert wider["rule"] == "probe" and wider["probe"] == pytest.approx(0.2 * radius)
    off = client.post("/v1/fleets", json=fleet_body("off", probe=0)).json()
    assert off["rule"] == "paper" and off["probe"] is None
    cases: list[tuple[str, dict[str, Any]]] = [
        ("bad", {"probe": -0.1}),
        ("mixed", {"rule": "consolidating", "probe": 0.1}),
        ("noise", {"rule": "consolidating", "annealing": {"scale": 5.0}}),
        ("unknown", {"rule": "kmeans"}),
    ]
    for name, extra in cases:
        bad = client.post("/v1/fleets", json=fleet_body(name, **extra))
        assert bad.status_code == 422, (name, bad.text)
        assert bad.headers["content-type"] == "application/problem+json"
        assert client.get(f"/v1/fleets/{name}").status_code == 404


def test_an_optimum_start_counts_the_sample_in_the_step_sizes(client: TestClient) -> None:
    rng = np.random.default_rng(12)
    sample: list[dict[str, Any]] = [
        {"edge": edge(int(e)), "offset": 0.0} for e in rng.integers(NET.n_edges, size=60)
    ]
    body = fleet_body(
        vehicles=[{"id": "a"}, {"id": "b"}, {"id": "c", "speed": 2.0}],
        start={"optimum": {"sample": sample}},
    )
    fleet = client.post("/v1/fleets", json=body).json()
    steps = client.get("/v1/fleets/f1/metrics").json()["step_size"]
    # independent count: each sample target goes to the vehicle with the least
    # either-way travel time (ties: lower index)
    starts = [
        NetPosition(NET.edge_index[v["position"]["edge"]], v["position"]["offset"])
        for v in fleet["vehicles"]
    ]
    speeds = np.array([v["speed"] for v in fleet["vehicles"]])
    points = [NetPosition(NET.edge_index[t["edge"]], 0.0) for t in sample]
    times = SPACE.cost_matrix(starts, points) / speeds[:, None]
    counts = np.bincount(times.argmin(axis=0), minlength=3)
    assert counts.sum() == 60
    a, power = fleet["step"]["a"], fleet["step"]["power"]
    for v, k in zip(fleet["vehicles"], counts, strict=True):
        assert steps[v["id"]] == pytest.approx(a / (k + 1) ** power)
    assert all(v["updates"] == 0 for v in fleet["vehicles"])


def test_an_optimum_start_is_where_simulate_starts_from_the_same_sample(
    client: TestClient,
) -> None:
    # a sample that repeats its places, as a call history does: the service and
    # ``simulate --start prior:N`` solve the p-median of one empirical distribution
    rng = np.random.default_rng(31)
    places = [NetPosition(int(e), 0.0) for e in rng.choice(NET.n_edges, size=25, replace=False)]
    sample = [places[int(i)] for i in rng.integers(len(places), size=200)]
    body = fleet_body(
        vehicles=[{"id": f"v{i}"} for i in range(6)],
        start={"optimum": {"sample": [{"edge": edge(p.edge), "offset": 0.0} for p in sample]}},
    )
    fleet = client.post("/v1/fleets", json=body)
    assert fleet.status_code == 201, fleet.text
    served = sorted(
        NetPosition(NET.edge_index[v["position"]["edge"]], v["position"]["offset"])
        for v in fleet.json()["vehicles"]
    )
    scenario = network_scenario(
        "drt", demand="hotspots:3", vehicles=6, cost="length", rng=np.random.default_rng(0)
    )
    simulated, used = starting_positions(scenario, sample, start="prior:200", power=1.0)
    assert used == 200
    assert served == sorted(simulated)


def test_the_answers_say_every_vehicle_that_moved(client: TestClient) -> None:
    rng = np.random.default_rng(14)
    vehicles = [
        {"id": f"v{i}", "position": {"edge": edge(int(e)), "offset": 0.0}}
        for i, e in enumerate(rng.choice(NET.n_edges, size=8, replace=False))
    ]
    fleet = client.post("/v1/fleets", json=fleet_body(vehicles=vehicles, probe=0.2)).json()
    known = {v["id"]: v["position"] for v in fleet["vehicles"]}
    backed = 0
    for e in rng.integers(NET.n_edges, size=300):
        r = client.post("/v1/fleets/f1/targets", json={"position": {"edge": edge(int(e))}})
        assert r.status_code == 200, r.text
        answer = r.json()
        for back in answer["backed_off"]:
            known[back["vehicle"]] = back["position"]
            backed += 1
        known[answer["moved"]] = answer["new_position"]
    assert backed > 0  # the probe did move vehicles back on this run
    now = client.get("/v1/fleets/f1").json()["vehicles"]
    assert {v["id"]: v["position"] for v in now} == known


def test_an_offset_of_minus_zero_is_the_edge_start_and_replays(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body("f")).raise_for_status()
    start = {"position": {"edge": edge(3), "offset": -0.0}}
    same = {"position": {"edge": edge(3), "offset": 0.0}}
    answers = [client.post("/v1/fleets/f/targets", json=t).json() for t in (start, same)]
    batch = client.post("/v1/fleets/f/targets:batch", json={"targets": [same, start]}).json()
    for answer in [*answers, *batch["results"]]:
        assert str(answer["target"]["offset"]) == "0.0"  # not "-0.0"
    report = client.app.state.fleets.verify("f")  # type: ignore[attr-defined]
    assert report["events"] == 5  # rebuilt from the log, each answer the same
