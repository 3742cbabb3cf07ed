"""One network, one identity: named at start-up or uploaded, gzipped or not (issue 25)."""

from __future__ import annotations

import gzip
import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from routing_svc import cli
from routing_svc.errors import StorageError
from routing_svc.service.app import create_app
from routing_svc.service.settings import Settings
from routing_svc.store import EventLog
from routing_svc.store.schema import networks
from tests.helpers import DRT, NET, edge, fleet_body

PLAIN = Path(DRT).read_bytes()
IDENTITY = hashlib.sha256(PLAIN).hexdigest()
OTHER = PLAIN + b"<!-- another file -->\n"


@pytest.fixture
def town_gz(tmp_path: Path) -> Path:
    """The DRT network as ``town.net.xml.gz``."""
    path = tmp_path / "town.net.xml.gz"
    path.write_bytes(gzip.compress(PLAIN))
    return path


def serve(db_url: str, tmp_path: Path, **start_up: Path) -> TestClient:
    """The app as ``routing-svc serve --net NAME=FILE ... --no-demo`` starts it."""
    settings = Settings(
        database_url=db_url,
        networks={name: str(path) for name, path in start_up.items()},
        data_dir=tmp_path / "networks",
    )
    return TestClient(create_app(settings))


def test_a_start_up_network_uploaded_again_is_the_same_network(
    db_url: str, tmp_path: Path, town_gz: Path
) -> None:
    with serve(db_url, tmp_path, town=town_gz) as client:
        started = client.get("/v1/networks/town").json()
        assert started["sha256"] == IDENTITY
        for body in (town_gz.read_bytes(), PLAIN, gzip.compress(PLAIN, compresslevel=1)):
            r = client.post("/v1/networks", params={"name": "town"}, content=body)
            assert r.status_code == 200, r.text
            assert r.json() == started
        assert [n["id"] for n in client.get("/v1/networks").json()["items"]] == ["town"]

        first = client.post("/v1/networks", content=gzip.compress(OTHER))
        again = client.post("/v1/networks", content=OTHER)
    assert first.status_code == 201 and again.status_code == 200, again.text
    assert first.json()["id"] == again.json()["id"] == hashlib.sha256(OTHER).hexdigest()[:12]


def test_other_content_under_a_known_name_is_a_conflict(
    db_url: str, tmp_path: Path, town_gz: Path
) -> None:
    other_gz = tmp_path / "other.net.xml.gz"
    other_gz.write_bytes(gzip.compress(OTHER))
    with serve(db_url, tmp_path, town=town_gz) as client:
        for body in (other_gz.read_bytes(), OTHER, other_gz.read_bytes()):
            r = client.post("/v1/networks", params={"name": "town"}, content=body)
            assert r.status_code == 409, r.text
            assert r.headers["content-type"] == "application/problem+json"
        assert client.get("/v1/networks/town").json()["sha256"] == IDENTITY
    with pytest.raises(StorageError, match="other content"), serve(db_url, tmp_path, town=other_gz):
        pass


def post_targets(client: TestClient, n: int) -> None:
    rng = np.random.default_rng(7)
    batch = [
        {"position": {"edge": edge(int(e)), "offset": 0.0}}
        for e in rng.integers(NET.n_edges, size=n)
    ]
    r = client.post("/v1/fleets/f1/targets:batch", json={"targets": batch})
    assert r.status_code == 200, r.text


def replay(db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> dict[str, Any]:
    """``routing-svc replay``: every fleet rebuilt from its log, checked against its snapshot."""
    capsys.readouterr()
    args = ["replay", "--database-url", db_url, "--data-dir", str(tmp_path / "networks")]
    assert cli.main(args) == 0
    report: dict[str, Any] = json.loads(capsys.readouterr().out)
    return report


@pytest.mark.parametrize("first", ["serve", "replay"])
def test_a_database_stored_under_the_former_hash_opens_and_replays(
    db_url: str, tmp_path: Path, town_gz: Path, capsys: pytest.CaptureFixture[str], first: str
) -> None:
    with serve(db_url, tmp_path, town=town_gz) as client:
        # a fleet of the probe rule stores its first snapshot at version 64
        client.post("/v1/fleets", json=fleet_body(network="town", rule="probe")).raise_for_status()
        post_targets(client, 70)  # past the first snapshot
        before = client.get("/v1/fleets/f1").json()
    # the start-up network as the former release stored it: the hash of the .gz bytes
    legacy = hashlib.sha256(town_gz.read_bytes()).hexdigest()
    engine = sa.create_engine(db_url)
    with engine.begin() as conn:
        conn.execute(sa.update(networks).where(networks.c.id == "town").values(sha256=legacy))
    engine.dispose()
    with EventLog(db_url) as log:
        assert log.get_network("town").sha256 == legacy

    def reopen() -> None:
        with serve(db_url, tmp_path, town=town_gz) as client:
            assert client.get("/v1/fleets/f1").json() == before
            assert client.get("/v1/networks/town").json()["sha256"] == IDENTITY
            r = client.post("/v1/networks", params={"name": "town"}, content=town_gz.read_bytes())
            assert r.status_code == 200, r.text

    def replays() -> None:
        (fleet,) = replay(db_url, tmp_path, capsys)["fleets"]
        assert fleet["ok"] and fleet["snapshot_identical"] is True
        assert fleet["version"] == before["version"]

    steps = [reopen, replays] if first == "serve" else [replays, reopen]
    for step in steps:
        step()
    with EventLog(db_url) as log:
        assert log.get_network("town").sha256 == IDENTITY
