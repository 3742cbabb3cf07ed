"""``kill -9`` while vehicles' states and targets stream in, with retried keys.

One client sends, in order, vehicle state changes (single and batch) and
targets, each with its ``Idempotency-Key``, retrying through two crashes. At
each crash every acknowledged key is stored once with its acknowledged seq and
``routing-svc replay`` rebuilds the stored state bit for bit; at the end the
fleet the server shows equals a serial replay of its whole log.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from routing_svc.store import EventLog
from tests.helpers import (
    LiveServer,
    edge,
    fleet_body,
    integrity,
    replay,
    serial_replay,
    target_stream,
)

REQUESTS = 120
KILLS = 2


def requests() -> list[tuple[str, str, dict[str, Any]]]:
    """``(method, path, body)`` in order: every third request a state change."""
    rng = np.random.default_rng(21)
    targets = iter(target_stream(8, REQUESTS))
    statuses = ("busy", "available", "offline", "available")
    out: list[tuple[str, str, dict[str, Any]]] = []
    for i in range(REQUESTS):
        vid = f"v{1 + i % 3}"
        if i % 6 == 0:
            where = {"edge": edge(int(rng.integers(0, 400))), "offset": 0.0}
            body = {"status": statuses[i % 4], "position": where, "timestamp": float(i)}
            out.append(("PUT", f"/v1/fleets/s1/vehicles/{vid}/state", body))
        elif i % 6 == 3:
            changes = [{"vehicle": f"v{k}", "status": statuses[(i + k) % 4]} for k in (1, 2, 3)]
            out.append(("POST", "/v1/fleets/s1/vehicles/state:batch", {"changes": changes}))
        else:
            out.append(("POST", "/v1/fleets/s1/targets", next(targets)))
    return out


def test_kill_9_during_state_updates_keeps_exactly_once(
    server: Callable[..., LiveServer], sqlite_url: str, tmp_path: Path
) -> None:
    live = server()
    httpx.post(live.url + "/v1/fleets", json=fleet_body("s1")).raise_for_status()
    acked: dict[str, int] = {}
    failures: list[str] = []
    done = threading.Event()

    def client() -> None:
        with httpx.Client(base_url=live.url, timeout=10) as http:
            for i, (method, path, body) in enumerate(requests()):
                key = f"s-{i}"
                while not done.is_set():
                    try:
                        r = http.request(method, path, json=body, headers={"Idempotency-Key": key})
                    except httpx.TransportError:
                        time.sleep(0.02)
                        continue
                    if r.status_code != 200:
                        failures.append(f"{key}: {r.status_code} {r.text}")
                        return
                    acked[key] = r.json()["seq"]
                    break

    thread = threading.Thread(target=client)
    thread.start()
    try:
        for k in range(KILLS):
            while len(acked) < (k + 0.5) * REQUESTS / (KILLS + 1) and not failures:
                time.sleep(0.005)
            assert failures == []
            live.kill()
            seen = dict(acked)
            stored = stored_keys(sqlite_url)
            assert all(stored.get(key) == seq for key, seq in seen.items())
            assert integrity(sqlite_url) == []
            replay(sqlite_url, tmp_path)
            live.start()
        thread.join(timeout=300)
    finally:
        done.set()
    assert failures == [] and len(acked) == REQUESTS
    shown = httpx.get(live.url + "/v1/fleets/s1").json()
    live.stop()
    assert stored_keys(sqlite_url) == acked
    assert shown == serial_replay(sqlite_url, tmp_path, "s1")
    assert any(v["status"] != "available" for v in shown["vehicles"])


def stored_keys(db_url: str) -> dict[str, int]:
    """``idempotency key -> seq`` of the fleet, checking that seq is contiguous."""
    with EventLog(db_url) as log:
        events = log.events_since("s1", 0)
    assert [e.seq for e in events] == list(range(1, len(events) + 1))
    keys = [str(e.idempotency_key) for e in events[1:]]
    assert len(set(keys)) == len(keys)
    return {str(e.idempotency_key): e.seq for e in events[1:]}
