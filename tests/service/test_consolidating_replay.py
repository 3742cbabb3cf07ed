"""A consolidating fleet through HTTP: recorded consolidations, restart and replay.

On SQLite and PostgreSQL (the ``db_url`` fixture). The default rule of a new fleet
consolidates after its 250th and 500th targets (``ConsolidationPolicy``: first 250,
growth 1.5); solved on the write path (``consolidation_workers=0``), each consolidation
is part of the result of the target that triggered it, and a restart or a replay
applies it as recorded. ``test_background_consolidation.py``: solved off it.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from routing_svc.service.app import create_app
from tests.helpers import (
    hotspot_stream,
    make_settings,
    post_batches,
    replay_report,
    spread_fleet_body,
)


class Service:
    """The app on one database; :meth:`restart` closes it and opens a new one on it."""

    def __init__(self, db_url: str, tmp_path: Path) -> None:
        self.db_url = db_url
        self.tmp_path = tmp_path
        self.client: TestClient | None = None

    def start(self) -> TestClient:
        client = TestClient(
            create_app(make_settings(self.db_url, self.tmp_path, consolidation_workers=0))
        )
        client.__enter__()
        self.client = client
        return client

    def stop(self) -> None:
        if self.client is not None:
            self.client.__exit__(None, None, None)
            self.client = None

    def restart(self) -> TestClient:
        self.stop()
        return self.start()


@pytest.fixture
def service(db_url: str, tmp_path: Path) -> Iterator[Service]:
    running = Service(db_url, tmp_path)
    running.start()
    yield running
    running.stop()


def test_consolidations_are_recorded_survive_a_restart_and_replay(
    service: Service,
    db_url: str,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    client = service.client
    assert client is not None
    targets = hotspot_stream(600)
    for fleet_id in ("steady", "restarted"):
        created = client.post("/v1/fleets", json=spread_fleet_body(fleet_id))
        assert created.status_code == 201, created.text
        assert created.json()["rule"] == "consolidating"

    steady = post_batches(client, "steady", targets)
    assert [r["seq"] for r in steady] == list(range(2, 602))
    consolidated = [r for r in steady if "consolidated" in r]
    # due at the 250th target (seq 251) and the 500th (seq 501): this stationary stream
    # starts no new epoch
    assert [r["seq"] for r in consolidated] == [251, 501]
    for r in consolidated:
        record = r["consolidated"]
        assert isinstance(record["accepted"], bool)
        assert len(record["positions"]) == len(record["updates"]) == 4
        assert all(set(p) == {"edge", "offset"} for p in record["positions"])
        assert record["sample"] == r["seq"] - 1  # every target so far is in the reservoir
        if record["accepted"]:
            assert sum(record["updates"]) == record["sample"]

    # the same targets, with a restart just after the consolidation of target 500: no
    # snapshot yet (the first at version 512), so the restart replays events 2..501 and
    # applies the recorded consolidations of seq 251 and 501 without solving them again
    head = post_batches(client, "restarted", targets[:500])
    assert [r["seq"] for r in head] == list(range(2, 502))
    assert head == steady[:500]
    before = client.get("/v1/fleets/restarted")
    assert before.status_code == 200

    def no_solving(*args: object, **kwargs: object) -> None:
        raise AssertionError("a restart solved a consolidation again")

    with monkeypatch.context() as patch:
        patch.setattr("routing_svc.sa.consolidation.consolidate", no_solving)
        client = service.restart()
        after = client.get("/v1/fleets/restarted")
        assert after.status_code == 200
        assert after.content == before.content
        assert after.json()["version"] == 501
        updates = {v["id"]: v["updates"] for v in before.json()["vehicles"]}
        assert client.get("/v1/fleets/restarted/metrics").json()["updates"] == updates

    tail = post_batches(client, "restarted", targets[500:])
    assert tail == steady[500:]
    restarted = client.get("/v1/fleets/restarted").json()
    reference = client.get("/v1/fleets/steady").json()
    assert restarted["version"] == reference["version"] == 601
    assert restarted["vehicles"] == reference["vehicles"]
    service.stop()

    report = replay_report(db_url, tmp_path, capsys)
    assert report["ok"] is True
    fleets = {f["fleet"]: f for f in report["fleets"]}
    assert set(fleets) == {"steady", "restarted"}
    for fleet in fleets.values():
        assert fleet["ok"] is True
        assert fleet["version"] == 601
        assert fleet["snapshot_identical"] is True
    # one state, however it was reached
    assert fleets["steady"]["state_sha256"] == fleets["restarted"]["state_sha256"]


def test_a_consolidating_fleet_takes_no_annealing(service: Service) -> None:
    client = service.client
    assert client is not None
    assert client.post("/v1/fleets", json=spread_fleet_body("kept")).status_code == 201
    kept = client.get("/v1/fleets/kept").content
    noisy = {"rule": "consolidating", "annealing": {"scale": 5.0}}
    for fleet_id in ("noisy", "kept"):
        r = client.post("/v1/fleets", json=spread_fleet_body(fleet_id, **noisy))
        assert r.status_code == 422, r.text
        assert r.headers["content-type"] == "application/problem+json"
    assert client.get("/v1/fleets/noisy").status_code == 404
    assert client.get("/v1/fleets/kept").content == kept
    ids = [f["id"] for f in client.get("/v1/fleets").json()["items"]]
    assert ids == ["kept"]
