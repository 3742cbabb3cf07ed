"""Two service processes on two ports sharing one PostgreSQL schema.

Per-fleet ordering comes from the fleet row lock (``SELECT ... FOR UPDATE``)
taken by every append, and each instance replays the events the other one
wrote before computing its own (``EventLog.append`` hands it the missed
events under the lock). Clients may therefore talk to any instance.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx

from routing_svc.sa.consolidation import ConsolidationPolicy
from routing_svc.service.runtime import SNAPSHOT_POSITIONS
from routing_svc.service.write_path import SNAPSHOT_EVERY
from tests.helpers import LiveServer, fleet_body, replay_ok, targets

FLEETS = ("f1", "f2")
RULES = {"f1": "consolidating", "f2": "probe"}
# a consolidating fleet's snapshot holds its reservoir: stored less often
EVERY = {
    "f1": SNAPSHOT_EVERY * -(-(3 + ConsolidationPolicy().reservoir) // SNAPSHOT_POSITIONS),
    "f2": SNAPSHOT_EVERY,
}


def create_fleets(server: LiveServer) -> None:
    for fid in FLEETS:
        body = fleet_body(fid, rule=RULES[fid])
        httpx.post(server.url + "/v1/fleets", json=body, timeout=60).raise_for_status()


def all_events(base: str, fleet_id: str) -> list[dict[str, Any]]:
    r = httpx.get(f"{base}/v1/fleets/{fleet_id}/events", params={"limit": 1000}, timeout=30)
    r.raise_for_status()
    items: list[dict[str, Any]] = r.json()["items"]
    return items


def check_replay(shared_pg_url: str, tmp_path: Path, expected_versions: dict[str, int]) -> None:
    """``routing-svc replay`` exits 0 and every fleet's snapshot is bit-identical."""
    report = replay_ok(shared_pg_url, tmp_path)
    assert report["ok"] is True
    by_fleet = {f["fleet"]: f for f in report["fleets"]}
    assert set(by_fleet) == set(expected_versions)
    for fid, version in expected_versions.items():
        # the instances stored a snapshot (about every EVERY versions); the serial
        # replay reproduces it bit for bit, then reaches the stored version
        if version >= EVERY[fid]:
            assert EVERY[fid] <= by_fleet[fid]["snapshot_version"] <= version, report
            assert by_fleet[fid]["snapshot_identical"] is True, report
        else:
            assert by_fleet[fid]["snapshot_version"] is None, report
        assert by_fleet[fid]["version"] == version


def test_concurrent_posts_through_two_instances(
    instances: Callable[[int], list[LiveServer]], shared_pg_url: str, tmp_path: Path
) -> None:
    a, b = instances(2)
    create_fleets(a)
    per_client = 24  # 72 targets per fleet: crosses f2's snapshot at version 64
    clients = 6  # each alternates instances and fleets request by request
    acked: dict[str, list[tuple[float, float, int]]] = {fid: [] for fid in FLEETS}
    sent_edges: dict[tuple[str, int], str] = {}
    errors: list[str] = []
    lock = threading.Lock()

    def client(n: int) -> None:
        bases = itertools.cycle([a.url, b.url] if n % 2 else [b.url, a.url])
        with httpx.Client(timeout=30) as http:
            for i, t in enumerate(targets(100 + n, per_client)):
                fid = FLEETS[(n + i) % 2]
                start = time.monotonic()
                r = http.post(f"{next(bases)}/v1/fleets/{fid}/targets", json=t)
                done = time.monotonic()
                if r.status_code != 200:
                    errors.append(r.text)
                    continue
                seq = r.json()["seq"]
                with lock:
                    acked[fid].append((start, done, seq))
                    sent_edges[(fid, seq)] = t["position"]["edge"]

    threads = [threading.Thread(target=client, args=(n,)) for n in range(clients)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert errors == []
    total = 0
    for fid in FLEETS:
        seqs = sorted(s for _, _, s in acked[fid])
        total += len(seqs)
        # contiguous and unique per fleet, whichever instance answered
        assert seqs == list(range(2, 2 + len(seqs)))
        # linearizable: a target sent after another was acknowledged gets a later seq
        for sent, _, seq in acked[fid]:
            assert all(seq > s for _, d, s in acked[fid] if d < sent)
        # both instances read the same log and the same state
        events_a, events_b = all_events(a.url, fid), all_events(b.url, fid)
        assert events_a == events_b
        assert [e["seq"] for e in events_a] == list(range(1, 2 + len(seqs)))
        for e in events_a[1:]:
            assert e["payload"]["target"]["edge"] == sent_edges[(fid, e["seq"])]
        state_a = httpx.get(f"{a.url}/v1/fleets/{fid}", timeout=30).json()
        state_b = httpx.get(f"{b.url}/v1/fleets/{fid}", timeout=30).json()
        assert state_a == state_b
        assert state_a["version"] == 1 + len(seqs)
    assert total == clients * per_client
    check_replay(shared_pg_url, tmp_path, {fid: 1 + len(acked[fid]) for fid in FLEETS})


def test_sigkill_one_instance_mid_stream(
    instances: Callable[[int], list[LiveServer]], shared_pg_url: str, tmp_path: Path
) -> None:
    a, b = instances(2)
    create_fleets(a)
    clients, per_client = 4, 40
    # (key, fleet, target) per client; keys are unique over the whole test
    work = [
        [(f"c{n}-{i}", FLEETS[(n + i) % 2], t) for i, t in enumerate(targets(200 + n, per_client))]
        for n in range(clients)
    ]
    acked: dict[str, tuple[str, int]] = {}  # key -> (fleet, seq)
    retried: list[str] = []
    failures: list[str] = []
    lock = threading.Lock()
    a_down = threading.Event()

    def post(http: httpx.Client, base: str, key: str, fid: str, t: Any) -> int | None:
        try:
            r = http.post(
                f"{base}/v1/fleets/{fid}/targets", json=t, headers={"Idempotency-Key": key}
            )
        except httpx.HTTPError:
            return None  # connection refused / reset: not acknowledged
        if r.status_code != 200:
            return None
        seq: int = r.json()["seq"]
        return seq

    def client(n: int) -> None:
        with httpx.Client(timeout=10) as http:
            for i, (key, fid, t) in enumerate(work[n]):
                first = a.url if (i + n) % 2 == 0 and not a_down.is_set() else b.url
                seq = post(http, first, key, fid, t)
                if seq is None:
                    # not acknowledged: retry with the same key against the survivor
                    with lock:
                        retried.append(key)
                    seq = post(http, b.url, key, fid, t)
                if seq is None:
                    failures.append(key)
                    continue
                with lock:
                    acked[key] = (fid, seq)

    threads = [threading.Thread(target=client, args=(n,)) for n in range(clients)]
    for th in threads:
        th.start()
    deadline = time.monotonic() + 60
    while len(acked) < clients * per_client // 3 and time.monotonic() < deadline:
        time.sleep(0.005)
    a.kill()  # SIGKILL, mid-stream
    a_down.set()
    acked_at_kill = len(acked)
    assert 0 < acked_at_kill < clients * per_client  # really mid-stream
    for th in threads:
        th.join()
    assert failures == []
    assert len(acked) == clients * per_client
    # the acknowledgements stand: retrying every key against the survivor answers the same seq
    with httpx.Client(base_url=b.url, timeout=30) as http:
        for client_work in work:
            for key, fid, t in client_work:
                r = http.post(f"/v1/fleets/{fid}/targets", json=t, headers={"Idempotency-Key": key})
                assert r.status_code == 200, r.text
                assert r.json()["seq"] == acked[key][1]
    target_of = {key: t for client_work in work for key, _, t in client_work}
    for fid in FLEETS:
        keys = [k for k, (f, _) in acked.items() if f == fid]
        events = all_events(b.url, fid)
        # exactly once: one event per key, contiguous seq, each where it was acknowledged
        assert [e["seq"] for e in events] == list(range(1, 2 + len(keys)))
        by_seq = {e["seq"]: e for e in events}
        assert sorted(acked[k][1] for k in keys) == list(range(2, 2 + len(keys)))
        for k in keys:
            edge = by_seq[acked[k][1]]["payload"]["target"]["edge"]
            assert edge == target_of[k]["position"]["edge"]
    check_replay(
        shared_pg_url,
        tmp_path,
        {fid: 1 + sum(1 for f, _ in acked.values() if f == fid) for fid in FLEETS},
    )
