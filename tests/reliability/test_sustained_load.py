"""Issue 6, item 8: mixed reads and writes at a steady rate.

CI: 20 s at 40 requests/s (70 % reads, 30 % target posts); ``ROUTING_SVC_SOAK_SCALE=30``
gives the issue's 10 minutes. No error; RSS growth below 50 MiB; p50/p99 reported.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import httpx
import numpy as np

from tests.helpers import LiveServer, fleet_body, record_figures, scaled, target_stream, vm_kib

RATE = 40.0
RSS_GROWTH_BOUND_MIB = 50


def test_steady_mixed_load(server: Callable[..., LiveServer], tmp_path: Path) -> None:
    live = server()
    assert live.process is not None
    duration = scaled(20)
    stream = target_stream(8, int(duration * RATE))
    rng = np.random.default_rng(8)
    latencies: list[float] = []
    errors: list[str] = []
    with httpx.Client(base_url=live.url, timeout=30) as http:
        http.post("/v1/fleets", json=fleet_body()).raise_for_status()
        for body in stream[:50]:  # warm-up
            http.post("/v1/fleets/f1/targets", json=body).raise_for_status()
        rss0 = vm_kib(live.process.pid, "VmRSS")
        start = time.monotonic()
        for i in range(int(duration * RATE)):
            wait = start + i / RATE - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            t0 = time.monotonic()
            u = rng.random()
            if u < 0.3:
                r = http.post("/v1/fleets/f1/targets", json=stream[i])
            elif u < 0.55:
                r = http.get("/v1/fleets/f1")
            elif u < 0.8:
                r = http.get("/v1/fleets/f1/metrics")
            else:
                r = http.get("/v1/fleets/f1/events", params={"after": max(0, i - 50)})
            latencies.append(time.monotonic() - t0)
            if r.status_code != 200:
                errors.append(f"{r.status_code} {r.text[:200]}")
        rss1 = vm_kib(live.process.pid, "VmRSS")
    assert errors == []
    growth = (rss1 - rss0) / 1024
    assert growth < RSS_GROWTH_BOUND_MIB
    ms = np.array(latencies) * 1000
    record_figures(
        "sustained_load",
        {
            "duration_s": duration,
            "rate_per_s": RATE,
            "requests": len(latencies),
            "errors": 0,
            "rss_start_mib": round(rss0 / 1024, 1),
            "rss_growth_mib": round(growth, 1),
            "p50_ms": round(float(np.percentile(ms, 50)), 2),
            "p99_ms": round(float(np.percentile(ms, 99)), 2),
            "max_ms": round(float(ms.max()), 2),
        },
        tmp_path,
    )
