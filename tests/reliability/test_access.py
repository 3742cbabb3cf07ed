"""Issue 6, item 7: the API key guards every write route; CORS allows only configured origins."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from routing_svc.service.app import create_app
from tests.helpers import every_route, fast_answers, fleet_body, make_settings, target_stream

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


def test_the_hot_route_keeps_the_key_and_cors_once(sqlite_url: str, tmp_path: Path) -> None:
    """``POST .../targets`` takes a short way in (the fast path): it still needs the key,
    gets CORS headers once, and what the fast path passes on (a bad body) is answered by
    the route with the same headers, once."""
    app = create_app(make_settings(sqlite_url, tmp_path, api_key="k3y", cors_origins=[ALLOWED]))
    key = {"X-API-Key": "k3y"}
    target = target_stream(5, 1)[0]
    with TestClient(app) as c:
        assert c.post("/v1/fleets", json=fleet_body(), headers=key).status_code == 201
        url = "/v1/fleets/f1/targets"
        before = fast_answers()
        r = c.post(url, json=target, headers={"Origin": ALLOWED, **key})
        assert r.status_code == 200 and fast_answers() == before + 1
        assert r.headers.get_list("access-control-allow-origin") == [ALLOWED]
        assert r.headers.get_list("vary") == ["Origin"]
        r = c.post(url, json=target, headers={"Origin": "https://evil.example", **key})
        assert r.status_code == 200 and "access-control-allow-origin" not in r.headers
        r = c.post(url, json=target, headers={"Origin": ALLOWED})
        assert r.status_code == 401
        assert r.headers["content-type"].startswith("application/problem+json")
        r = c.post(url, content=b"{", headers={"Origin": ALLOWED, **key})
        assert r.status_code == 422
        assert r.headers["content-type"].startswith("application/problem+json")
        assert r.headers.get_list("access-control-allow-origin") == [ALLOWED]
        assert r.headers.get_list("vary") == ["Origin"]
        assert fast_answers() == before + 2
        assert c.get("/v1/fleets/f1", headers=key).json()["version"] == 3
