"""Issue 24: bounded waits on the database, through a real network partition.

Two instances share one PostgreSQL schema: A reaches it through an in-test TCP
proxy, B directly. The proxy then stops forwarding in both directions while it
keeps every connection open and accepts new ones (packets vanish; nothing
errors out), and later heals. During the partition every request to A answers
within its configured deadline (503 problem+json with ``Retry-After``), A's
``/healthz`` answers 503 within its own deadline, and B goes on serving the same
fleet. After healing, A's health is 200 again, its pool has every connection
back, and keyed retries apply every target exactly once.
"""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

import httpx
from sqlalchemy.engine import make_url

from tests.conftest import pg_url
from tests.helpers import (
    LiveServer,
    check_log,
    check_store_problem,
    fleet_body,
    record_figures,
    replay,
    settle_keys,
    target_stream,
    wait_health,
)
from tests.reliability.pgproxy import TcpProxy

REQUEST_S = 1.5
HEALTH_S = 1.0
SLACK_S = 2.0  # scheduling on two shared cores, process start-up of nothing: answers only
BOUNDS = (
    "--request-timeout-s", str(REQUEST_S), "--health-timeout-s", str(HEALTH_S),
    "--retry-after-s", "1", "--db-connect-timeout-s", "2", "--db-pool-timeout-s", "1",
    "--db-lent-timeout-s", "1", "--db-statement-timeout-ms", "1000",
    "--db-lock-timeout-ms", "1000", "--db-idle-in-transaction-timeout-ms", "1000",
)  # fmt: skip


def timed(call: Any) -> tuple[httpx.Response, float]:
    t0 = time.monotonic()
    r = call()
    return r, time.monotonic() - t0


def cut_connections(url: str) -> float:
    text = httpx.get(url + "/metrics", timeout=10).text
    found = re.search(r"^routing_svc_db_connections_cut_total (\S+)$", text, re.M)
    return float(found.group(1)) if found else 0.0


def test_partition_bounded_answers_other_instance_serves_then_heal(
    pg_database: str, pg_schema: str, tmp_path: Path
) -> None:
    direct = pg_url(pg_database, schema=pg_schema)
    upstream = make_url(direct)
    assert upstream.host is not None and upstream.port is not None
    started = time.monotonic()
    with TcpProxy(upstream.host, upstream.port) as proxy:
        via_proxy = upstream.set(port=proxy.port).render_as_string(hide_password=False)
        b = LiveServer(direct, tmp_path, extra=BOUNDS).start()
        a = LiveServer(via_proxy, tmp_path, extra=BOUNDS).start()
        secrets = (upstream.host, str(proxy.port), str(upstream.port))
        keyed = {f"part-{i}": body for i, body in enumerate(target_stream(5, 40))}
        keys = iter(keyed)
        acked: dict[str, bytes] = {}
        try:
            with (
                httpx.Client(base_url=a.url, timeout=30) as to_a,
                httpx.Client(base_url=b.url, timeout=30) as to_b,
            ):

                def post(http: httpx.Client) -> tuple[str, httpx.Response, float]:
                    key = next(keys)
                    r, took = timed(
                        lambda: http.post(
                            "/v1/fleets/f1/targets",
                            json=keyed[key],
                            headers={"Idempotency-Key": key},
                        )
                    )
                    if r.status_code == 200:
                        acked[key] = r.content
                    return key, r, took

                to_b.post("/v1/fleets", json=fleet_body()).raise_for_status()
                for http in (to_a, to_b) * 4:
                    assert post(http)[1].status_code == 200
                in_use_before = to_a.get("/healthz").json()["connections_in_use"]
                cuts_before = cut_connections(a.url)

                proxy.partition()
                partition_started = time.monotonic()
                slowest = {"post": 0.0, "get": 0.0, "healthz": 0.0, "b_post": 0.0}
                a_types: set[str] = set()
                health_503 = 0
                for _ in range(3):
                    _, r, took = post(to_a)
                    slowest["post"] = max(slowest["post"], took)
                    assert took <= REQUEST_S + SLACK_S, took
                    if r.status_code != 200:
                        a_types.add(check_store_problem(r, secrets, a.log))
                    r, took = timed(lambda: to_a.get("/v1/fleets/f1"))
                    slowest["get"] = max(slowest["get"], took)
                    assert took <= REQUEST_S + SLACK_S, took
                    if r.status_code != 200:
                        a_types.add(check_store_problem(r, secrets, a.log))
                    r, took = timed(lambda: to_a.get("/healthz"))
                    slowest["healthz"] = max(slowest["healthz"], took)
                    assert took <= HEALTH_S + SLACK_S, took
                    assert r.status_code == 503, r.text
                    assert int(r.headers["retry-after"]) >= 1 and r.json()["reason"]
                    health_503 += 1
                    _, r, took = post(to_b)
                    slowest["b_post"] = max(slowest["b_post"], took)
                    assert r.status_code == 200, r.text  # the other instance serves
                assert a_types, "the partitioned instance answered everything"
                partitioned_s = time.monotonic() - partition_started

                proxy.forward()
                _, healed_s = wait_health(a.url, 200)
                deadline = time.monotonic() + 15
                while (
                    in_use := to_a.get("/healthz").json()["connections_in_use"]
                ) != in_use_before:
                    assert time.monotonic() < deadline, (in_use, in_use_before)
                    time.sleep(0.1)
                cuts = cut_connections(a.url) - cuts_before
                settle_keys(to_a, "f1", keyed, acked)
                a_fleet = to_a.get("/v1/fleets/f1").json()
                b_fleet = to_b.get("/v1/fleets/f1").json()
        finally:
            a.stop()
            b.stop()
    assert a_fleet == b_fleet
    assert cuts >= 1  # hung calls were freed by shutting their sockets
    applied = check_log(direct, "f1", acked)
    assert a_fleet["version"] == 1 + applied
    replay(direct, tmp_path)
    record_figures(
        "partition",
        {
            "bounds_s": {"request": REQUEST_S, "healthz": HEALTH_S},
            "slowest_answer_during_partition_s": {k: round(v, 2) for k, v in slowest.items()},
            "a_problem_types": sorted(a_types),
            "healthz_503_answers": health_503,
            "partition_s": round(partitioned_s, 1),
            "health_200_after_heal_s": round(healed_s, 2),
            "connections_cut": cuts,
            "connections_in_use_after_eq_before": in_use_before,
            "applied_once": applied,
            "elapsed_s": round(time.monotonic() - started, 1),
        },
        tmp_path,
    )
