"""Issue 6, item 7: the API key guards every write route; CORS allows only configured origins."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from routing_svc.service.app import create_app
from tests.reliability.workload import fleet_body
from tests.service.conftest import make_settings
from tests.service.test_bad_input import every_route

ALLOWED = "https://dispatch.example"


def test_every_write_route_needs_the_key(sqlite_url: str, tmp_path: Path) -> None:
    app = create_app(make_settings(sqlite_url, tmp_path, api_key="k3y"))
    with TestClient(app) as c:
        writes = [(m, p) for m, p in every_route(app.routes) if m not in {"GET", "HEAD", "OPTIONS"}]
        assert len(writes) >= 7
        for method, path in writes:
            url = path.replace("{fleet_id}", "f1").replace("{network_id}", "drt")
            for headers in ({}, {"X-API-Key": "wrong"}):
                r = c.request(method, url, json={}, headers=headers)
                assert r.status_code == 401, (method, path)
                assert r.headers["content-type"].startswith("application/problem+json")
        assert c.get("/v1/fleets").json()["items"] == []
        ok = c.post("/v1/fleets", json=fleet_body(), headers={"X-API-Key": "k3y"})
        assert ok.status_code == 201


def test_cors_allows_only_configured_origins(sqlite_url: str, tmp_path: Path) -> None:
    app = create_app(make_settings(sqlite_url, tmp_path, cors_origins=[ALLOWED]))
    with TestClient(app) as c:
        r = c.get("/v1/fleets", headers={"Origin": ALLOWED})
        assert r.headers.get("access-control-allow-origin") == ALLOWED
        r = c.get("/v1/fleets", headers={"Origin": "https://evil.example"})
        assert "access-control-allow-origin" not in r.headers
        pre = {"Access-Control-Request-Method": "POST"}
        r = c.options("/v1/fleets", headers={"Origin": ALLOWED, **pre})
        assert r.status_code == 200 and r.headers["access-control-allow-origin"] == ALLOWED
        r = c.options("/v1/fleets", headers={"Origin": "https://evil.example", **pre})
        assert "access-control-allow-origin" not in r.headers
