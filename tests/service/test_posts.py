"""``GET /v1/fleets/{id}/posts`` through HTTP, on SQLite and PostgreSQL, against brute
force over the subsets of the references and the matchings (scipy's full Dijkstra,
:meth:`RoadSpace.cost_matrix`)."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
from fastapi.testclient import TestClient

from tests.service.test_vehicle_state import (
    PROBLEM,
    SPACE,
    edge,
    fleet_body,
    position,
    random_targets,
)


def test_posts_are_the_best_references_for_the_available_vehicles(client: TestClient) -> None:
    body = fleet_body(rule="consolidating", objective="routing")
    client.post("/v1/fleets", json=body).raise_for_status()
    targets = random_targets(np.random.default_rng(11), 40)
    batch = {"targets": [{"position": t} for t in targets]}
    client.post("/v1/fleets/f1/targets:batch", json=batch).raise_for_status()
    elsewhere = {"edge": edge(500), "offset": 0.5}
    changes = [
        {"vehicle": "v0", "status": "busy"},
        {"vehicle": "v3", "status": "busy"},
        {"vehicle": "v4", "status": "available", "position": elsewhere},
    ]
    client.post("/v1/fleets/f1/vehicles/state:batch", json={"changes": changes}).raise_for_status()
    fleet = client.get("/v1/fleets/f1").json()

    answer = client.get("/v1/fleets/f1/posts")
    assert answer.status_code == 200, answer.text
    posts = answer.json()
    assert posts["version"] == fleet["version"]
    vehicles = fleet["vehicles"]
    references = [position(v["reference"]) for v in vehicles]
    free = [v for v in vehicles if v["status"] == "available"]
    assert [p["vehicle"] for p in posts["posts"]] == [v["id"] for v in free]

    # the best 4 of the 6 references for the 40 targets the fleet has seen
    demand = SPACE.cost_matrix(references, [position(t) for t in targets])
    values = {
        subset: float(demand[list(subset)].min(axis=0).sum())
        for subset in itertools.combinations(range(len(references)), len(free))
    }
    ranked = sorted(values, key=values.__getitem__)
    assert values[ranked[0]] < values[ranked[1]]  # a unique best: the check means something
    ids = [v["id"] for v in vehicles]
    assert {p["reference_of"] for p in posts["posts"]} == {ids[i] for i in ranked[0]}
    for post in posts["posts"]:
        owner = ids.index(post["reference_of"])
        assert post["position"] == vehicles[owner]["reference"]

    # matched at the least total travel time from where the available vehicles are
    here = [position(v["current"]) for v in free]
    travel = SPACE.cost_matrix(here, [references[i] for i in ranked[0]])
    least = min(
        sum(travel[r, c] for r, c in enumerate(order))
        for order in itertools.permutations(range(len(free)))
    )
    assert math.isclose(sum(p["time"] for p in posts["posts"]), least, rel_tol=1e-9)
    for row, post in enumerate(posts["posts"]):
        column = list(ranked[0]).index(ids.index(post["reference_of"]))
        assert math.isclose(post["time"], travel[row, column], rel_tol=1e-9, abs_tol=1e-9)

    # reading the posts changes nothing (the version counts the applied events)
    assert client.get("/v1/fleets/f1").json() == fleet


def test_with_every_vehicle_available_each_holds_its_reference(client: TestClient) -> None:
    client.post("/v1/fleets", json=fleet_body()).raise_for_status()
    fleet = client.get("/v1/fleets/f1").json()
    posts = client.get("/v1/fleets/f1/posts").json()["posts"]
    assert [(p["vehicle"], p["reference_of"], p["time"]) for p in posts] == [
        (v["id"], v["id"], 0.0) for v in fleet["vehicles"]
    ]
    assert [p["position"] for p in posts] == [v["reference"] for v in fleet["vehicles"]]


def test_posts_of_an_unknown_fleet_are_a_problem(client: TestClient) -> None:
    r = client.get("/v1/fleets/nope/posts")
    assert r.status_code == 404 and r.headers["content-type"].startswith(PROBLEM)
    body: dict[str, Any] = r.json()
    assert body["status"] == 404
