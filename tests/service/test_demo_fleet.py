"""The demo fleet of the quick start: created once, and a deleted one does not stop a restart."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from routing_svc.service.app import create_app
from tests.helpers import make_settings


def test_a_deleted_demo_fleet_stays_deleted_and_the_service_starts_again(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'events.db'}"
    settings = make_settings(url, tmp_path, demo_fleet=True)
    with TestClient(create_app(settings)) as client:
        created = client.get("/v1/fleets/demo")
        assert created.status_code == 200
        assert len(created.json()["vehicles"]) == 8
    with TestClient(create_app(settings)) as client:  # a restart keeps the same fleet
        again = client.get("/v1/fleets/demo")
        assert again.status_code == 200 and again.json() == created.json()
        assert client.delete("/v1/fleets/demo").status_code == 204
    with TestClient(create_app(settings)) as client:  # ids are never reused
        assert client.get("/healthz").status_code == 200
        gone = client.get("/v1/fleets/demo")
        assert gone.status_code == 404
        assert gone.headers["content-type"].startswith("application/problem+json")
        assert client.get("/v1/fleets").json()["items"] == []
