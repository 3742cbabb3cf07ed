"""Who writes the targets of the REST API: the event loop (SQLite) or the writer thread, and
what happens when the event loop cannot take the database's write lock at once."""

from __future__ import annotations

import re
import sqlite3
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx

from tests.helpers import LiveServer, fleet_body, targets


def commits(metrics_text: str) -> dict[str, float]:
    """``routing_svc_commits_total`` by writer."""
    found = re.findall(r'^routing_svc_commits_total\{writer="(\w+)"\} (\S+)$', metrics_text, re.M)
    return {writer: float(value) for writer, value in found}


def test_each_backend_has_its_writer(live_server: Callable[..., LiveServer], db_url: str) -> None:
    server = live_server()
    with httpx.Client(base_url=server.url, timeout=60) as http:
        http.post("/v1/fleets", json=fleet_body()).raise_for_status()
        bodies = targets(3, 40)
        with ThreadPoolExecutor(8) as pool:
            answers = list(pool.map(lambda t: http.post("/v1/fleets/f1/targets", json=t), bodies))
        assert [a.status_code for a in answers] == [200] * len(bodies)
        assert sorted(a.json()["seq"] for a in answers) == list(range(2, 2 + len(bodies)))
        counted = commits(http.get("/metrics").text)
    if db_url.startswith("sqlite"):
        # staged on the event loop, all of them (nothing else was writing)
        assert counted.get("event_loop", 0) >= 1
        assert counted.get("thread", 0) == 0
    else:
        assert counted.get("event_loop", 0) == 0
        assert counted.get("thread", 0) >= 1


def test_a_held_write_lock_sends_targets_to_a_thread_and_the_loop_keeps_serving(
    tmp_path: Path,
) -> None:
    db_url = f"sqlite:///{tmp_path / 'locked.db'}"
    server = LiveServer(db_url, tmp_path).start()
    try:
        with httpx.Client(base_url=server.url, timeout=60) as http:
            http.post("/v1/fleets", json=fleet_body()).raise_for_status()
            http.post("/v1/fleets", json=fleet_body("f2")).raise_for_status()
            # another process takes the database's write lock
            other = sqlite3.connect(tmp_path / "locked.db", isolation_level=None)
            other.execute("BEGIN IMMEDIATE")
            answers: list[httpx.Response] = []
            poster = threading.Thread(
                target=lambda: answers.append(
                    httpx.post(server.url + "/v1/fleets/f1/targets", json=targets(4, 1)[0],
                               timeout=60)
                )
            )  # fmt: skip
            poster.start()
            try:
                time.sleep(0.5)
                assert answers == []  # it waits for the lock ...
                # ... on a worker thread: the event loop still answers, reads included
                assert http.get("/healthz").status_code == 200
                assert http.get("/v1/fleets/f2").json()["version"] == 1
                assert answers == []
            finally:
                other.execute("ROLLBACK")
                other.close()
            poster.join(timeout=60)
            assert [a.status_code for a in answers] == [200]
            assert answers[0].json()["seq"] == 2
            counted = commits(http.get("/metrics").text)
            assert counted.get("thread", 0) == 1
            # with the lock free again, the event loop writes the next target itself
            before = counted.get("event_loop", 0)
            second = http.post("/v1/fleets/f1/targets", json=targets(5, 1)[0])
            assert second.status_code == 200 and second.json()["seq"] == 3
            assert commits(http.get("/metrics").text).get("event_loop", 0) == before + 1
            events = http.get("/v1/fleets/f1/events").json()["items"]
            assert [e["seq"] for e in events] == [1, 2, 3]
    finally:
        server.stop()


def test_a_fleet_deleted_elsewhere_fails_alone(tmp_path: Path) -> None:
    """The event loop's transaction fails for the whole group; the worker thread then
    commits fleet by fleet, so only the deleted fleet's targets fail."""
    from routing_svc.service.fleets import FleetService
    from routing_svc.service.networks import NetworkRegistry
    from routing_svc.store import EventLog

    db_url = f"sqlite:///{tmp_path / 'deleted.db'}"
    server = LiveServer(db_url, tmp_path).start()
    try:
        with httpx.Client(base_url=server.url, timeout=60) as http:
            for fleet_id in ("f1", "f2"):
                http.post("/v1/fleets", json=fleet_body(fleet_id)).raise_for_status()
                first = http.post(f"/v1/fleets/{fleet_id}/targets", json=targets(6, 1)[0])
                assert first.status_code == 200  # both fleets are in the server's memory
            with EventLog(db_url) as log:  # another instance deletes f2
                registry = NetworkRegistry(data_dir=tmp_path / "networks", max_bytes=1 << 26)
                FleetService(log, registry, recent_window=10).delete_fleet("f2")
            bodies = [("f1" if i % 2 else "f2", t) for i, t in enumerate(targets(7, 24))]
            with ThreadPoolExecutor(8) as pool:
                answers = list(
                    pool.map(
                        lambda ft: http.post(f"/v1/fleets/{ft[0]}/targets", json=ft[1]), bodies
                    )
                )
            by_fleet = {
                f: [a.status_code for (g, _), a in zip(bodies, answers, strict=True) if g == f]
                for f in ("f1", "f2")
            }
            assert by_fleet["f1"] == [200] * 12
            assert by_fleet["f2"] == [404] * 12
            events = http.get("/v1/fleets/f1/events").json()["items"]
            assert [e["seq"] for e in events] == list(range(1, 15))
    finally:
        server.stop()


def test_start_up_objects_are_kept_out_of_full_collections(tmp_path: Path) -> None:
    """While the app runs, what start-up built is frozen (out of the cyclic collector's full
    passes, which stalled the event loop); after shutdown it is collectable again."""
    import gc

    from fastapi.testclient import TestClient

    from routing_svc.service.app import create_app
    from tests.helpers import make_settings

    assert gc.get_freeze_count() == 0
    with TestClient(create_app(make_settings(f"sqlite:///{tmp_path / 'gc.db'}", tmp_path))) as c:
        assert c.get("/healthz").status_code == 200
        assert gc.get_freeze_count() > 10_000  # the network, the modules, the app
    assert gc.get_freeze_count() == 0
