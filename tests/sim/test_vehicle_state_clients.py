"""Vehicle states through both clients: HTTP (a live server) and in-process give the same."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from routing_svc import errors
from routing_svc.client import FleetClient, HttpFleetClient
from routing_svc.service.inprocess import InProcessFleetClient

FLEET: dict[str, Any] = {
    "id": "f",
    "network": "grid",
    "cost": "time",
    "vehicles": [
        {"id": "v0", "position": {"edge": "A0A1", "offset": 100.0}},
        {"id": "v1", "position": {"edge": "F5F4", "offset": 100.0}},
    ],
}


def _exercise(client: FleetClient) -> list[Any]:
    """Set states one at a time and in a batch; what the service answered and dispatched."""
    client.create_fleet(FLEET)
    seen: list[Any] = []
    one = client.put_vehicle_state("f", "v0", {"status": "busy", "timestamp": 10.0})
    seen.append([(v["id"], v["status"]) for v in one["vehicles"]])
    target = {"edge": "A1A2", "offset": 50.0}
    seen.append(client.assign("f", target)["dispatch"]["vehicles"][0]["vehicle"])
    batch = client.put_vehicle_states(
        "f",
        [
            {"vehicle": "v1", "status": "busy", "timestamp": 20.0},
            {"vehicle": "v0", "status": "available", "position": {"edge": "C3C4", "offset": 5.0}},
        ],
    )
    seen.append([(v["id"], v["status"], v["current"]["edge"]) for v in batch["vehicles"]])
    seen.append(client.assign("f", target)["dispatch"]["vehicles"][0]["vehicle"])
    client.put_vehicle_state("f", "v0", {"status": "busy"})
    seen.append(client.assign("f", target)["dispatch"]["status"])
    statuses = {v["id"]: v["status"] for v in client.get_fleet("f")["vehicles"]}
    seen.append(statuses)
    with pytest.raises(errors.RoutingSvcError):
        client.put_vehicle_state("f", "nobody", {"status": "busy"})
    with pytest.raises(errors.InvalidInput):
        client.put_vehicle_state("f", "v0", {"status": "asleep"})
    with pytest.raises(errors.RoutingSvcError):  # back in time: nothing of the batch applies
        client.put_vehicle_states(
            "f",
            [
                {"vehicle": "v0", "status": "available"},
                {"vehicle": "v1", "status": "available", "timestamp": 5.0},
            ],
        )
    assert {v["id"]: v["status"] for v in client.get_fleet("f")["vehicles"]} == statuses
    return seen


def test_http_and_in_process_clients_agree(fleet_server: str, grid_net: Path) -> None:
    with HttpFleetClient(fleet_server) as remote:
        over_http = _exercise(remote)
    with InProcessFleetClient() as local:
        local.add_network(grid_net, name="grid")
        in_process = _exercise(local)
    assert over_http == in_process
    assert over_http[1] == "v1" and over_http[3] == "v0" and over_http[4] == "queued"
    assert over_http[5] == {"v0": "busy", "v1": "busy"}
