"""A fleet restricted to stands through the HTTP API of a live server: created, fed,
restored from its log by a second server; bad stands are a 422 and create nothing."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import httpx

from tests.helpers import LiveServer, edge, fleet_body, targets

STANDS = [
    {"edge": edge(5), "offset": 0.0, "capacity": 2},
    {"edge": edge(50), "offset": 1.0, "capacity": 1},
    {"edge": edge(200), "offset": 0.5, "capacity": 1},
    {"edge": edge(5), "offset": 0.0, "capacity": 1},  # the first stand again: capacities add
]


def test_a_fleet_with_stands(live_server: Callable[..., LiveServer]) -> None:
    server = live_server()
    body = fleet_body(stands=STANDS, rule="consolidating")
    created = httpx.post(server.url + "/v1/fleets", json=body)
    assert created.status_code == 201, created.text
    events = httpx.get(server.url + "/v1/fleets/f1/events").json()["items"]
    stored = events[0]["payload"]["config"]["stands"]
    assert stored == [
        {"edge": edge(5), "offset": 0.0, "capacity": 3},
        {"edge": edge(50), "offset": 1.0, "capacity": 1},
        {"edge": edge(200), "offset": 0.5, "capacity": 1},
    ]
    batch = httpx.post(
        server.url + "/v1/fleets/f1/targets:batch", json={"targets": targets(3, 300)}
    )
    assert batch.status_code == 200, batch.text
    before = httpx.get(server.url + "/v1/fleets/f1").json()
    assert before["targets"] == 300
    # started at the optimum of a sample: at the optimum over the stands
    sample = [t["position"] for t in targets(4, 30)]
    vehicles = [{"id": v["id"]} for v in body["vehicles"]]
    started = httpx.post(
        server.url + "/v1/fleets",
        json={**body, "id": "f3", "vehicles": vehicles, "start": {"optimum": {"sample": sample}}},
    )
    assert started.status_code == 201, started.text
    stand_places = {(s["edge"], s["offset"]) for s in stored}
    at = [(v["position"]["edge"], v["position"]["offset"]) for v in started.json()["vehicles"]]
    assert set(at) <= stand_places
    assert at.count((edge(50), 1.0)) <= 1 and at.count((edge(200), 0.5)) <= 1
    server.stop()
    again = live_server()  # a second server restores the fleet from the log
    after = httpx.get(again.url + "/v1/fleets/f1").json()
    assert after == before


def problem_of(server: LiveServer, body: dict[str, Any]) -> dict[str, Any]:
    r = httpx.post(server.url + "/v1/fleets", json=body)
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    problem: dict[str, Any] = r.json()
    return problem


BAD_STANDS = [
    ([{"edge": "no-such-edge", "offset": 0.0, "capacity": 5}], "not on the network"),
    ([{"edge": edge(5), "offset": 1e6, "capacity": 5}], "off the edge"),
    ([{"edge": edge(5), "offset": -1.0, "capacity": 5}], "offset"),
    ([{"edge": edge(5), "offset": 0.0, "capacity": 0}], "capacity"),
    ([{"edge": edge(5), "offset": 0.0, "capacity": -2}], "capacity"),
    ([{"edge": edge(5), "offset": 0.0, "capacity": 1.5}], "capacity"),
    ([{"edge": edge(5), "offset": 0.0, "capacity": "3"}], "capacity"),
    ([{"edge": edge(5), "offset": 0.0}], "capacity"),
    ([{"edge": edge(5), "offset": 0.0, "capacity": 1, "x": 1}], "x"),
    ([], "stands"),
    ([{"edge": edge(5), "offset": 0.0, "capacity": 1}, {"edge": edge(9), "capacity": 1}],
     "exceed the total capacity 2"),
]  # fmt: skip


def test_bad_stands_create_nothing(live_server: Callable[..., LiveServer]) -> None:
    server = live_server()
    for stands, detail in BAD_STANDS:
        problem = problem_of(server, fleet_body("f2", stands=stands))
        assert detail in problem["detail"], (stands, problem)
        assert httpx.get(server.url + "/v1/fleets/f2").status_code == 404
        assert httpx.get(server.url + "/v1/fleets").json()["items"] == []
