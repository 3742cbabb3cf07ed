"""The dashboard's routes in process: the page, its assets, and the redirect from ``/``."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from routing_svc.service.app import create_app
from routing_svc.service.routes.dashboard import static_assets
from tests.helpers import make_settings

SVG_NAMESPACE = "http://www.w3.org/2000/svg"


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    with TestClient(create_app(make_settings(f"sqlite:///{tmp_path / 'e.db'}", tmp_path))) as c:
        yield c


def test_home_redirects_to_the_dashboard(client: TestClient) -> None:
    r = client.get("/", follow_redirects=False)
    assert r.status_code == 307 and r.headers["location"] == "/dashboard"
    assert client.get("/").url.path == "/dashboard"


def test_the_page_allows_only_its_own_origin(client: TestClient) -> None:
    r = client.get("/dashboard")
    assert r.status_code == 200
    assert r.headers["content-type"] == "text/html; charset=utf-8"
    policy = r.headers["content-security-policy"]
    assert "default-src 'self'" in policy and "connect-src 'self'" in policy
    assert '<script type="module" src="/dashboard/static/js/main.js">' in r.text
    assert "%BASE%" not in r.text


def test_every_referenced_asset_is_served(client: TestClient) -> None:
    page = client.get("/dashboard").text
    wanted = set(re.findall(r'(?:href|src)="/dashboard/static/([^"]+)"', page))
    for name, body in static_assets().items():
        if name.endswith(".js"):
            folder = name.rsplit("/", 1)[0]
            imports = re.findall(r'from "\./([^"]+)"', body.decode())
            wanted |= {f"{folder}/{module}" for module in imports}
    assert {"dashboard.css", "js/main.js", "js/map.js", "js/charts.js"} <= wanted
    for name in wanted:
        r = client.get(f"/dashboard/static/{name}")
        assert r.status_code == 200, name
        kind = "text/css" if name.endswith(".css") else "text/javascript"
        assert r.headers["content-type"] == f"{kind}; charset=utf-8"


def test_nothing_outside_the_static_folder_is_served(client: TestClient) -> None:
    for name in ["nope.js", "..%2Fapp.py", "js/..%2F..%2Fapp.py", "index.html"]:
        r = client.get(f"/dashboard/static/{name}")
        assert r.status_code == 404, name
        assert r.headers["content-type"] == "application/problem+json"


def test_no_asset_refers_to_another_origin() -> None:
    for name, body in static_assets().items():
        text = body.decode().replace(SVG_NAMESPACE, "")
        assert not re.search(r"https?://|//[a-z0-9.-]+\.[a-z]{2,}/", text), name


def test_the_page_follows_the_root_path(tmp_path: Path) -> None:
    app = create_app(make_settings(f"sqlite:///{tmp_path / 'e.db'}", tmp_path))
    with TestClient(app, root_path="/fleet-svc") as client:
        page = client.get("/dashboard").text
        assert 'data-base="/fleet-svc"' in page
        assert 'src="/fleet-svc/dashboard/static/js/main.js"' in page
        r = client.get("/", follow_redirects=False)
        assert r.headers["location"] == "/fleet-svc/dashboard"


def test_assets_are_revalidated_by_etag(client: TestClient) -> None:
    first = client.get("/dashboard/static/js/main.js")
    assert first.headers["cache-control"] == "no-cache"
    again = client.get(
        "/dashboard/static/js/main.js", headers={"If-None-Match": first.headers["etag"]}
    )
    assert again.status_code == 304 and again.content == b""
    other = client.get(
        "/dashboard/static/js/map.js", headers={"If-None-Match": first.headers["etag"]}
    )
    assert other.status_code == 200 and other.headers["etag"] != first.headers["etag"]
