"""``POST /v1/networks/{id}/positions:resolve``: each place on the network, or why not."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from routing_svc.network.snapping import point_on_edge
from tests.helpers import NET, edge


def test_places_resolve_as_targets_do_and_the_others_say_why(client: TestClient) -> None:
    x, y = point_on_edge(NET, 7, 2.0)
    length = float(NET.length[3])
    body = {
        "positions": [
            {"edge": edge(3), "offset": length / 2},
            {"edge": "no-such-edge"},
            {"edge": edge(3), "offset": length + 1.0},
            {"x": x, "y": y},
            {"x": x + 1e6, "y": y},
        ]
    }
    before = client.get("/v1/networks").json()
    answer = client.post("/v1/networks/drt/positions:resolve", json=body)
    assert answer.status_code == 200
    got = answer.json()
    first = got["positions"][0]
    assert (first["edge"], first["offset"]) == (edge(3), pytest.approx(length / 2))
    on_edge = got["positions"][3]
    assert on_edge["edge"] == edge(7) and on_edge["offset"] == pytest.approx(2.0, abs=1e-6)
    assert [p is None for p in got["positions"]] == [False, True, True, False, True]
    assert [u["index"] for u in got["unresolved"]] == [1, 2, 4]
    assert "no-such-edge" in got["unresolved"][0]["detail"]
    assert "beyond the end" in got["unresolved"][1]["detail"]
    # the same as a target of a fleet would be resolved: /assign agrees
    fleet = {"id": "r", "network": "drt", "vehicles": [{"id": "a", "position": {"edge": edge(0)}}]}
    assert client.post("/v1/fleets", json=fleet).status_code == 201
    assigned = client.post("/v1/fleets/r/assign", json={"position": {"x": x, "y": y}}).json()
    assert (assigned["target"]["edge"], assigned["target"]["offset"]) == (
        on_edge["edge"],
        on_edge["offset"],
    )
    assert client.get("/v1/networks").json() == before


@pytest.mark.parametrize(
    "body",
    [{}, {"positions": []}, {"positions": [{"lon": 200.0, "lat": 0.0}]}, {"positions": [{}]}],
)
def test_a_malformed_request_is_a_422_problem(client: TestClient, body: object) -> None:
    answer = client.post("/v1/networks/drt/positions:resolve", json=body)
    assert answer.status_code == 422
    assert answer.headers["content-type"] == "application/problem+json"


def test_an_unknown_network_is_a_404_problem(client: TestClient) -> None:
    answer = client.post(
        "/v1/networks/nowhere/positions:resolve", json={"positions": [{"x": 0, "y": 0}]}
    )
    assert answer.status_code == 404
    assert answer.headers["content-type"] == "application/problem+json"
