"""Issue 22: storage faults as clients and load balancers see them.

Real faults, each then repaired while the server runs:

- the SQLite database's file system fills up (a size-limited tmpfs that the test
  mounts, as root, and grows afterwards with ``mount -o remount``);
- PostgreSQL goes away (an in-test TCP proxy in front of the shared server closes
  its listener and resets every connection) and comes back.

Every answer while the store fails is a 503 problem+json with a stable ``type``,
a short ``detail``, an ``error_id`` (the server logs the cause under it) and
``Retry-After``; no answer names the database's host, port, file or driver, nor a
library link. ``/healthz`` turns 503 with a reason and back to 200 once writes
work. Keyed retries then apply every target exactly once, nothing acknowledged is
lost, and ``routing-svc replay`` reproduces the stored state.
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from sqlalchemy.engine import make_url

from tests.conftest import pg_url
from tests.helpers import (
    LiveServer,
    check_log,
    check_store_problem,
    fleet_body,
    integrity,
    record_figures,
    replay,
    settle_keys,
    shows_secret,
    target_stream,
    wait_health,
)
from tests.reliability.pgproxy import TcpProxy


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 1 MiB tmpfs mounted for this test (as root), unmounted afterwards."""
    mount = tmp_path / "disk"
    mount.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)], check=True)
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


def test_full_sqlite_disk_then_more_space(tmp_path: Path, small_disk: Path) -> None:
    db = small_disk / "events.db"
    db_url = f"sqlite:///{db}"
    bounds = ("--health-min-free-bytes", "32768", "--retry-after-s", "1")
    live = LiveServer(db_url, tmp_path, extra=bounds).start()
    started = time.monotonic()
    try:
        with httpx.Client(base_url=live.url, timeout=30) as http:
            http.post("/v1/fleets", json=fleet_body()).raise_for_status()
            keyed: dict[str, dict[str, Any]] = {}
            acked: dict[str, bytes] = {}
            failed: list[str] = []
            before_full = 0
            types: set[str] = set()
            for i, body in enumerate(target_stream(7, 5000)):
                key = f"disk-{i}"
                keyed[key] = body
                r = http.post("/v1/fleets/f1/targets", json=body, headers={"Idempotency-Key": key})
                if r.status_code == 200:
                    acked[key] = r.content
                    continue
                types.add(check_store_problem(r, (str(db), str(small_disk)), live.log))
                before_full = before_full or len(acked)
                failed.append(key)
                if len(failed) == 5:
                    break
            assert failed, "the disk never filled up"
            assert types == {"urn:routing-svc:problem:storage-unavailable"}
            assert "database or disk is full" in live.log.read_text(errors="replace")
            full, _ = wait_health(live.url, 503)
            assert "space" in full["reason"]
            assert http.get("/v1/fleets/f1").status_code == 200  # reads go on

            subprocess.run(["mount", "-o", "remount,size=16m", str(small_disk)], check=True)
            _, recovery_s = wait_health(live.url, 200)
            settle_keys(http, "f1", keyed, acked)
    finally:
        live.stop()
    applied = check_log(db_url, "f1", acked)
    assert integrity(db_url) == []
    replay(db_url, tmp_path)
    record_figures(
        "disk_full",
        {
            "acknowledged_before_full": before_full,
            "refused_while_full": len(failed),
            "health_while_full": full["reason"],
            "health_200_after_more_space_s": round(recovery_s, 2),
            "applied_once": applied,
            "elapsed_s": round(time.monotonic() - started, 1),
        },
        tmp_path,
    )


def test_postgresql_down_then_back(pg_database: str, pg_schema: str, tmp_path: Path) -> None:
    direct = pg_url(pg_database, schema=pg_schema)
    upstream = make_url(direct)
    assert upstream.host is not None and upstream.port is not None
    bounds = (
        "--request-timeout-s", "3", "--health-timeout-s", "1", "--retry-after-s", "1",
        "--db-connect-timeout-s", "2", "--db-pool-timeout-s", "1", "--db-lent-timeout-s", "2",
    )  # fmt: skip
    started = time.monotonic()
    with TcpProxy(upstream.host, upstream.port) as proxy:
        via_proxy = upstream.set(port=proxy.port).render_as_string(hide_password=False)
        live = LiveServer(via_proxy, tmp_path, extra=bounds).start()
        secrets = (upstream.host, f":{proxy.port}", str(proxy.port), "5432")
        try:
            with httpx.Client(base_url=live.url, timeout=30) as http:
                http.post("/v1/fleets", json=fleet_body()).raise_for_status()
                stream = target_stream(11, 30)
                keyed = {f"pg-{i}": body for i, body in enumerate(stream)}
                acked: dict[str, bytes] = {}
                keys = list(keyed)
                for key in keys[:10]:
                    r = http.post(
                        "/v1/fleets/f1/targets", json=keyed[key], headers={"Idempotency-Key": key}
                    )
                    assert r.status_code == 200, r.text
                    acked[key] = r.content
                proxy.down()
                types: set[str] = set()
                slowest = 0.0
                for key in keys[10:20]:
                    t0 = time.monotonic()
                    r = http.post(
                        "/v1/fleets/f1/targets", json=keyed[key], headers={"Idempotency-Key": key}
                    )
                    slowest = max(slowest, time.monotonic() - t0)
                    types.add(check_store_problem(r, secrets, live.log))
                for path in ("/v1/fleets/f1", "/v1/fleets/f1/events", "/v1/fleets"):
                    check_store_problem(http.get(path), secrets, live.log)
                check_store_problem(
                    http.post("/v1/fleets", json=fleet_body("f2")), secrets, live.log
                )
                down, _ = wait_health(live.url, 503)
                assert not shows_secret(str(down), secrets)
                proxy.forward()
                _, recovery_s = wait_health(live.url, 200)
                settle_keys(http, "f1", keyed, acked)
        finally:
            live.stop()
    applied = check_log(direct, "f1", acked)
    replay(direct, tmp_path)
    record_figures(
        "postgresql_down",
        {
            "problem_types_while_down": sorted(types),
            "slowest_write_answer_while_down_s": round(slowest, 2),
            "health_while_down": down["reason"],
            "health_200_after_back_s": round(recovery_s, 2),
            "applied_once": applied,
            "elapsed_s": round(time.monotonic() - started, 1),
        },
        tmp_path,
    )
