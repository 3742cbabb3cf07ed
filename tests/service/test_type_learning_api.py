"""A fleet of two types through HTTP learns per type: each type consolidates on its own
targets, the result names the vehicles it moved, and a restart and a replay apply the
recorded consolidations (on SQLite and PostgreSQL, the ``db_url`` fixture)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from routing_svc.service.app import create_app
from tests.helpers import edge, hotspot_stream, make_settings, post_batches, replay_report

KINDS = {"va": "A", "vb": "A", "vc": "B", "vd": "B"}


def typed_body(fleet_id: str, **extra: Any) -> dict[str, Any]:
    """Two vehicles of type A and two of type B spread over DRT."""
    return {
        "id": fleet_id,
        "network": "drt",
        "vehicles": [
            {"id": vid, "type": kind, "position": {"edge": edge(e), "offset": 0.0}}
            for (vid, kind), e in zip(KINDS.items(), (0, 100, 300, 500), strict=True)
        ],
        **extra,
    }


def typed_stream(n: int, both: bool = False) -> list[dict[str, Any]]:
    """``n`` targets; the even ones need one A, the odd ones one B, every fifth any one
    (``both``: an A and a B)."""
    targets = hotspot_stream(n)
    for i, body in enumerate(targets):
        if i % 5 != 4:
            body["requires"] = ["A" if i % 2 == 0 else "B"]
        elif both:
            body["requires"] = ["A", "B"]
    return targets


def client_of(db_url: str, tmp_path: Path, workers: int) -> TestClient:
    return TestClient(create_app(make_settings(db_url, tmp_path, consolidation_workers=workers)))


def test_each_type_consolidates_on_its_targets_and_replays(
    db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    targets = typed_stream(800)
    with client_of(db_url, tmp_path, 0) as client:
        created = client.post("/v1/fleets", json=typed_body("typed"))
        assert created.status_code == 201, created.text
        assert created.json()["rule"] == "consolidating"
        results = post_batches(client, "typed", targets[:700])
        before = client.get("/v1/fleets/typed")
        assert before.status_code == 200
    consolidated = [(r["seq"], r["consolidated"]) for r in results if "consolidated" in r]
    # each type's first is due at the 250th target it was fed: those that need it and
    # those for any one vehicle (every fifth, which feed both); a target makes one at
    # most (A's first, by name), the other waits for its own next target
    fed = {
        kind: [i for i, t in enumerate(targets[:700]) if t.get("requires") in (None, [kind])]
        for kind in ("A", "B")
    }
    due_a = fed["A"][249]
    due_b = next(i for i in fed["B"][249:] if i != due_a)
    by_type: dict[str, list[int]] = {}
    for seq, record in consolidated:
        kinds = {KINDS[v] for v in record["vehicles"]}
        assert len(kinds) == 1 and len(record["vehicles"]) == 2
        assert len(record["positions"]) == len(record["updates"]) == 2
        (kind,) = kinds
        assert targets[seq - 2].get("requires") in (None, [kind])
        assert record["sample"] == (250 if kind == "A" else fed["B"].index(due_b) + 1)
        by_type.setdefault(kind, []).append(seq)
    assert by_type == {"A": [due_a + 2], "B": [due_b + 2]}
    assert due_a < 500  # before either type had 250 targets that needed it alone

    with client_of(db_url, tmp_path, 0) as client:  # restart: replays the recorded ones
        after = client.get("/v1/fleets/typed")
        assert after.content == before.content
        tail = post_batches(client, "typed", targets[700:])
        assert [r["seq"] for r in tail] == list(range(702, 802))
    report = replay_report(db_url, tmp_path, capsys)
    (fleet,) = report["fleets"]
    assert fleet["ok"] is True and fleet["snapshot_identical"] is True


def test_solved_by_the_workers_each_type_consolidates_and_replays(
    db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    targets = typed_stream(900, both=True)
    with client_of(db_url, tmp_path, 1) as client:
        assert client.post("/v1/fleets", json=typed_body("typed")).status_code == 201
        results = post_batches(client, "typed", targets)
    made = [r for r in results if "consolidated" in r]
    kinds = sorted(KINDS[r["consolidated"]["vehicles"][0]] for r in made)
    assert kinds[0] == "A" and kinds[-1] == "B"
    # targets that need an A and a B feed both: each type's first is due at its 250th
    assert made[0]["seq"] < 502  # before either type had 250 targets of one type alone
    report = replay_report(db_url, tmp_path, capsys)
    (fleet,) = report["fleets"]
    assert fleet["ok"] is True and fleet["snapshot_identical"] is True


def test_fleets_that_cannot_learn_per_type_keep_the_probe_rule(db_url: str, tmp_path: Path) -> None:
    mixed = typed_body("mixed")
    mixed["vehicles"][3]["speed"] = 1.5  # type B of two speeds
    with client_of(db_url, tmp_path, 0) as client:
        created = client.post("/v1/fleets", json=mixed)
        assert created.status_code == 201, created.text
        assert created.json()["rule"] == "probe"
