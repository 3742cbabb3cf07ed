"""Group commit through a real server: concurrent posts share transactions."""

from __future__ import annotations

import re
import threading
from collections.abc import Callable
from typing import Any

import httpx

from tests.helpers import LiveServer, fleet_body, targets

THREADS = 16
PER_THREAD = 12


def group_histogram(metrics_text: str) -> tuple[float, float, float]:
    """``(transactions, requests, transactions with one request)`` from ``/metrics``."""

    def value(pattern: str) -> float:
        match = re.search(pattern, metrics_text, re.MULTILINE)
        assert match is not None, pattern
        return float(match.group(1))

    count = value(r"^routing_svc_commit_group_size_count (\S+)$")
    total = value(r"^routing_svc_commit_group_size_sum (\S+)$")
    singles = value(r'^routing_svc_commit_group_size_bucket\{le="1\.0"\} (\S+)$')
    return count, total, singles


def test_concurrent_posts_share_transactions(
    live_server: Callable[..., LiveServer], db_url: str
) -> None:
    server = live_server()
    httpx.post(server.url + "/v1/fleets", json=fleet_body()).raise_for_status()
    start = threading.Barrier(THREADS)
    answers: list[tuple[str, str, dict[str, Any]]] = []  # (key, edge, answer)
    errors: list[str] = []
    lock = threading.Lock()

    def client(worker: int) -> None:
        with httpx.Client(base_url=server.url, timeout=60) as http:
            start.wait()
            for i, t in enumerate(targets(100 + worker, PER_THREAD)):
                key = f"w{worker}-{i}"
                r = http.post("/v1/fleets/f1/targets", json=t, headers={"Idempotency-Key": key})
                with lock:
                    if r.status_code != 200:
                        errors.append(r.text)
                    else:
                        answers.append((key, t["position"]["edge"], r.json()))

    threads = [threading.Thread(target=client, args=(i,)) for i in range(THREADS)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert errors == []
    n = THREADS * PER_THREAD
    # seq stays contiguous and every answer matches the log
    assert sorted(a["seq"] for _, _, a in answers) == list(range(2, 2 + n))
    with httpx.Client(base_url=server.url, timeout=60) as http:
        events = http.get("/v1/fleets/f1/events", params={"limit": 1000}).json()["items"]
        assert [e["seq"] for e in events] == list(range(1, 2 + n))
        by_seq = {e["seq"]: e for e in events}
        for _, edge_id, answer in answers:
            stored = by_seq[answer["seq"]]
            assert stored["result"] == answer
            assert stored["payload"]["target"]["edge"] == edge_id
        assert http.get("/v1/fleets/f1").json()["version"] == 1 + n
        # a retry returns the stored answer byte for byte and applies nothing
        key, edge_id, answer = answers[n // 2]
        retry = http.post(
            "/v1/fleets/f1/targets",
            json={"position": {"edge": edge_id, "offset": 0.0}},
            headers={"Idempotency-Key": key},
        )
        assert retry.status_code == 200 and retry.json() == answer
        assert http.get("/v1/fleets/f1").json()["version"] == 1 + n
        metrics = http.get("/metrics").text
    transactions, requests, singles = group_histogram(metrics)
    assert requests == n + 1  # every post (and the retry) was committed exactly once
    assert transactions < requests  # several targets shared a transaction
    assert singles < transactions  # at least one group held more than one target
