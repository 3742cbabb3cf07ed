"""Issue 6, item 4: SIGTERM under load.

Every 2xx answer is committed (its seq is in the log with the same result), and
every other request fails cleanly: a connection error or a 503 problem, never a
wrong answer.
"""

from __future__ import annotations

import json
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx

from routing_svc.store import EventLog
from tests.helpers import (
    LiveServer,
    fleet_body,
    integrity,
    record_figures,
    replay,
    scaled,
    target_stream,
)

CLIENTS = 6


def test_sigterm_under_load_commits_every_acknowledged_target(
    server: Callable[..., LiveServer], sqlite_url: str, tmp_path: Path
) -> None:
    live = server()
    httpx.post(live.url + "/v1/fleets", json=fleet_body()).raise_for_status()
    answers: list[dict[str, Any]] = []
    unclean: list[str] = []
    clean_failures = 0
    lock = threading.Lock()

    def client(worker: int) -> None:
        nonlocal clean_failures
        with httpx.Client(base_url=live.url, timeout=30) as http:
            for body in target_stream(200 + worker, 3000):
                try:
                    r = http.post("/v1/fleets/f1/targets", json=body)
                except httpx.TransportError:
                    with lock:
                        clean_failures += 1
                    return  # the server is gone: a clean failure
                if r.status_code == 200:
                    with lock:
                        answers.append({"body": body, "answer": r.json()})
                elif r.status_code == 503 and r.headers["content-type"].startswith(
                    "application/problem+json"
                ):
                    with lock:
                        clean_failures += 1
                else:
                    unclean.append(f"{r.status_code} {r.text}")
                    return

    threads = [threading.Thread(target=client, args=(i,)) for i in range(CLIENTS)]
    for th in threads:
        th.start()
    goal = scaled(150)
    while len(answers) < goal and not unclean:
        time.sleep(0.005)
    assert live.process is not None
    live.process.send_signal(signal.SIGTERM)  # to the server process only, as a supervisor would
    exit_code = live.process.wait(timeout=60)
    for th in threads:
        th.join(timeout=60)
    assert unclean == []
    # uvicorn re-raises the signal once its graceful shutdown is done: -SIGTERM, not a crash
    assert exit_code in (0, -signal.SIGTERM), live.log.read_text()[-2000:]
    assert "Traceback" not in live.log.read_text()
    with EventLog(sqlite_url) as log:
        events = {e.seq: e for e in log.events_since("f1", 0)}
    for item in answers:
        event = events[item["answer"]["seq"]]
        assert event.kind == "target"
        assert json.loads(event.result_json or "null") == item["answer"]
        assert json.loads(event.payload_json)["target"]["edge"] == item["body"]["position"]["edge"]
    assert len(events) >= 1 + len(answers)  # in-flight requests may have committed unanswered
    assert len(events) - 1 - len(answers) <= CLIENTS
    assert integrity(sqlite_url) == []
    replay(sqlite_url, tmp_path)
    record_figures(
        "graceful_shutdown",
        {
            "acknowledged": len(answers),
            "committed": len(events) - 1,
            "clean_failures": clean_failures,
            "wrong_answers": 0,
            "exit_code": exit_code,
        },
        tmp_path,
    )
