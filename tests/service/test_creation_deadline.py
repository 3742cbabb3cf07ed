"""Creating a fleet: the request's deadline bounds its waits on the store, not the solving
of its start and reference optimum (:func:`routing_svc.service.deadline.deadline_paused`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from routing_svc.service import creation
from routing_svc.service.fleets import FleetService
from routing_svc.service.routes import fleets as fleet_routes
from tests.helpers import NET, edge, fleet_body

DEADLINE_S = 0.3


def optimum_body(vehicles: int, samples: int) -> dict[str, Any]:
    rng = np.random.default_rng(5)
    edges = rng.integers(NET.n_edges, size=samples)
    sample = [{"edge": edge(int(e)), "offset": 0.0} for e in edges]
    return fleet_body(
        vehicles=[{"id": f"v{i}"} for i in range(vehicles)], start={"optimum": {"sample": sample}}
    )


def test_a_fleet_solved_at_its_optimum_is_created_and_answered(
    make_client: Callable[..., TestClient], db_url: str
) -> None:
    client = make_client(db_url, request_timeout_s=DEADLINE_S)
    r = client.post("/v1/fleets", json=optimum_body(30, 5000))
    assert r.status_code == 201, r.text
    assert len(r.json()["vehicles"]) == 30
    assert client.get("/v1/fleets/f1").json()["version"] == 1


def test_solving_longer_than_the_deadline_still_answers_the_creation(
    make_client: Callable[..., TestClient], db_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    def slow(*args: Any) -> dict[str, Any]:
        time.sleep(3 * DEADLINE_S)  # a solve that takes three deadlines
        return creation.build_created_payload(*args)

    monkeypatch.setattr(fleet_routes, "build_created_payload", slow)
    client = make_client(db_url, request_timeout_s=DEADLINE_S)
    r = client.post("/v1/fleets", json=optimum_body(4, 200))
    assert r.status_code == 201, r.text
    events = client.get("/v1/fleets/f1/events", params={"after": 0}).json()["items"]
    assert [e["kind"] for e in events] == ["fleet_created"]


def test_a_slow_store_after_the_solve_still_meets_the_deadline(
    make_client: Callable[..., TestClient], db_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    real_commit = FleetService.commit_fleet

    def slow_solve(*args: Any) -> dict[str, Any]:
        time.sleep(2 * DEADLINE_S)
        return creation.build_created_payload(*args)

    def slow_commit(self: FleetService, *args: Any) -> dict[str, Any]:
        time.sleep(3 * DEADLINE_S)  # the store's part alone takes three deadlines
        return real_commit(self, *args)

    monkeypatch.setattr(fleet_routes, "build_created_payload", slow_solve)
    monkeypatch.setattr(FleetService, "commit_fleet", slow_commit)
    client = make_client(db_url, request_timeout_s=DEADLINE_S)
    r = client.post("/v1/fleets", json=optimum_body(4, 200))
    assert r.status_code == 503, r.text
    assert r.headers["content-type"] == "application/problem+json"
    assert r.json()["type"] == "urn:routing-svc:problem:commit-outcome-unknown"
    assert int(r.headers["retry-after"]) >= 1
    # the outcome the answer could not know: the write went on, once
    for _ in range(200):
        if client.get("/v1/fleets/f1").status_code == 200:
            break
        time.sleep(0.05)
    events = client.get("/v1/fleets/f1/events", params={"after": 0}).json()["items"]
    assert [e["kind"] for e in events] == ["fleet_created"]
    # the answer says how to settle it, and the same body does
    assert "(a fleet's creation: the same body)" in r.json()["detail"]
    monkeypatch.undo()
    again = client.post("/v1/fleets", json=optimum_body(4, 200))
    assert again.status_code == 409, again.text
    assert [e["kind"] for e in client.get("/v1/fleets/f1/events").json()["items"]] == [
        "fleet_created"
    ]
