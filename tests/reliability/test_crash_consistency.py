"""Issue 6, item 1: ``kill -9`` at random moments under load over several fleets.

Clients retry every target with its ``Idempotency-Key`` until it is acknowledged.
At each crash (server dead) the stored log is checked: every acknowledged key is
applied with the seq it was acknowledged with, no key is applied twice, seq is
contiguous, ``integrity_check`` is clean and ``routing-svc replay`` rebuilds the
stored state bit for bit. At the end applied keys == acknowledged keys.

CI size: 1,000 targets, 3 kills (about a minute). ``ROUTING_SVC_SOAK_SCALE=10`` gives
the full size of the issue: 10,000 targets and 20 kills.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import numpy as np

from routing_svc.store import EventLog
from tests.helpers import (
    SCALE,
    LiveServer,
    fleet_body,
    integrity,
    record_figures,
    replay,
    scaled,
    target_stream,
)

FLEETS = ("c1", "c2", "c3", "c4")


def stored_keys(db_url: str) -> dict[str, dict[str, int]]:
    """``fleet -> {idempotency key: seq}``, checking seq contiguity and key uniqueness."""
    out: dict[str, dict[str, int]] = {}
    with EventLog(db_url) as log:
        for fleet in FLEETS:
            events = log.events_since(fleet, 0)
            assert [e.seq for e in events] == list(range(1, len(events) + 1)), fleet
            keys = [e.idempotency_key for e in events[1:]]
            assert None not in keys
            assert len(set(keys)) == len(keys), f"{fleet}: a key was applied twice"
            out[fleet] = {str(e.idempotency_key): e.seq for e in events[1:]}
    return out


def test_kill_9_under_load_keeps_exactly_once(
    server: Callable[..., LiveServer], sqlite_url: str, tmp_path: Path
) -> None:
    n_targets = scaled(1000)
    n_kills = max(1, round(3 * SCALE**0.824))  # scale 1 -> 3 kills, 10 -> 20 kills
    per_fleet = n_targets // len(FLEETS)
    live = server()
    for fleet in FLEETS:
        httpx.post(live.url + "/v1/fleets", json=fleet_body(fleet)).raise_for_status()
    streams = {f: target_stream(i, per_fleet) for i, f in enumerate(FLEETS)}
    acked: dict[str, tuple[str, int]] = {}  # key -> (fleet, seq)
    failures: list[str] = []
    lock = threading.Lock()
    done = threading.Event()

    def client(fleet: str) -> None:
        with httpx.Client(base_url=live.url, timeout=10) as http:
            for i, body in enumerate(streams[fleet]):
                key = f"{fleet}-{i}"
                while not done.is_set():
                    try:
                        r = http.post(
                            f"/v1/fleets/{fleet}/targets",
                            json=body,
                            headers={"Idempotency-Key": key},
                        )
                    except httpx.TransportError:
                        time.sleep(0.02)  # the server is down: retry the same key
                        continue
                    if r.status_code != 200:
                        failures.append(f"{key}: {r.status_code} {r.text}")
                        return
                    with lock:
                        acked[key] = (fleet, r.json()["seq"])
                    break

    threads = [threading.Thread(target=client, args=(f,)) for f in FLEETS]
    for th in threads:
        th.start()
    rng = np.random.default_rng(6)
    started = time.monotonic()
    restarts: list[float] = []
    try:
        for k in range(n_kills):
            # a random moment inside the k-th slice of the load
            goal = (k + rng.uniform(0.2, 0.9)) * per_fleet * len(FLEETS) / (n_kills + 1)
            while len(acked) < goal and not failures:
                time.sleep(0.005)
            assert failures == []
            live.kill()
            with lock:
                seen = dict(acked)
            stored = stored_keys(sqlite_url)
            applied_keys = {key for keys in stored.values() for key in keys}
            for key, (fleet, seq) in seen.items():
                assert stored[fleet].get(key) == seq, key
            # applied but not acknowledged: only the requests in flight at the kill
            assert len(applied_keys - set(seen)) <= len(FLEETS)
            assert integrity(sqlite_url) == []
            replay(sqlite_url, tmp_path)
            t0 = time.monotonic()
            live.start()
            restarts.append(time.monotonic() - t0)
        for th in threads:
            th.join(timeout=600)
    finally:
        done.set()
    assert failures == []
    assert len(acked) == per_fleet * len(FLEETS)
    live.stop()
    stored = stored_keys(sqlite_url)
    applied = {key: (fleet, seq) for fleet, keys in stored.items() for key, seq in keys.items()}
    assert applied == acked  # exactly once, with the acknowledged seq
    assert integrity(sqlite_url) == []
    report = replay(sqlite_url, tmp_path)
    assert all(f["snapshot_identical"] is not False for f in report["fleets"])
    record_figures(
        "crash_consistency",
        {
            "targets": len(acked),
            "fleets": len(FLEETS),
            "kills": n_kills,
            "applied_twice": 0,
            "lost": 0,
            "max_restart_s": round(max(restarts), 2),
            "elapsed_s": round(time.monotonic() - started, 1),
        },
        tmp_path,
    )
