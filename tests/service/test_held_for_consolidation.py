"""A fleet whose targets must wait for its consolidation's solve is held on the write path:
its writes stay queued, in order, while other fleets are written and the event loop
answers; the solve's end releases them, and the log replays as served.

The solver here hands out a future that the test answers (with the job's own solve), so
that the moment the solve ends is the test's; the worker process itself is tested in
``test_background_consolidation.py``.
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from routing_svc.sa.consolidation import ConsolidationJob, ConsolidationPolicy
from routing_svc.service.schemas import TargetSpec
from routing_svc.service.write_path.pending import QueuedWrite, take_batch
from tests.helpers import hotspot_stream, post_batches, replay_ok, spread_fleet_body

FIRST = ConsolidationPolicy().first
APPLY_BY = FIRST + FIRST // 2
"""The first consolidation falls due at target ``FIRST``; the target that comes once the
fleet has seen this many waits for it."""


class HandSolver:
    """Takes jobs; their answers come when the test gives them."""

    def __init__(self) -> None:
        self.jobs: list[tuple[ConsolidationJob[Any], Future[Any]]] = []

    def submit(self, job: ConsolidationJob[Any]) -> Future[Any]:
        answer: Future[Any] = Future()
        self.jobs.append((job, answer))
        return answer

    def close(self) -> None:
        for _, answer in self.jobs:
            answer.cancel()


def in_background(call: Callable[[], Any]) -> tuple[threading.Thread, list[Any]]:
    out: list[Any] = []
    thread = threading.Thread(target=lambda: out.append(call()), daemon=True)
    thread.start()
    return thread, out


@pytest.mark.parametrize("writer", ["http", "thread"])
def test_a_fleet_waiting_for_its_consolidation_holds_only_its_own_writes(
    db_url: str, tmp_path: Path, make_client: Callable[..., TestClient], writer: str
) -> None:
    client = make_client(db_url)
    service = client.app.state.fleets  # type: ignore[attr-defined]
    solver = HandSolver()
    service.solver = solver
    for fleet_id in ("waits", "other"):
        assert client.post("/v1/fleets", json=spread_fleet_body(fleet_id)).status_code == 201
    stream = hotspot_stream(APPLY_BY + 2)
    post_batches(client, "waits", stream[:FIRST])
    [(job, answer)] = solver.jobs  # due at the 250th target, handed to the solver
    assert job.apply_by == APPLY_BY
    post_batches(client, "waits", stream[FIRST:APPLY_BY])  # up to apply_by: not held

    def post_one(body: dict[str, Any]) -> Any:
        if writer == "http":
            r = client.post("/v1/fleets/waits/targets", json=body)
            assert r.status_code == 200, r.text
            return r.json()
        results, _ = service.post_targets("waits", [TargetSpec.model_validate(body)])
        return json.loads(results[0])

    first, first_out = in_background(lambda: post_one(stream[APPLY_BY]))
    time.sleep(0.3)
    second, second_out = in_background(lambda: post_one(stream[APPLY_BY + 1]))
    time.sleep(0.5)
    assert first_out == [] and second_out == []  # held while the solve runs
    for body in hotspot_stream(20):  # the other fleet is written meanwhile
        r = client.post("/v1/fleets/other/targets", json=body)
        assert r.status_code == 200, r.text
    assert client.get("/v1/fleets/other").json()["version"] == 21
    assert client.get("/v1/fleets/waits").json()["version"] == 1 + APPLY_BY
    assert first_out == [] and second_out == []

    answer.set_result(job.solve())
    first.join(timeout=60)
    second.join(timeout=60)
    [held_first], [held_second] = first_out, second_out
    assert (held_first["seq"], held_second["seq"]) == (APPLY_BY + 2, APPLY_BY + 3)  # in order
    assert "consolidated" in held_first  # the target that waited applied it
    assert replay_ok(db_url, tmp_path)["ok"] is True


def queued(fleet_id: str, size: int = 1) -> QueuedWrite:
    return QueuedWrite(fleet_id, lambda runtime: [], None, None, size)


def test_a_batch_leaves_a_held_fleet_queued_in_order_and_takes_the_others() -> None:
    queue = deque(
        [queued("a"), queued("b"), queued("a", 5), queued("c", 254), queued("b"), queued("a")]
    )
    order = list(queue)
    asked: list[tuple[str, int]] = []

    def holds(fleet_id: str, events_ahead: int) -> bool:
        asked.append((fleet_id, events_ahead))
        return fleet_id == "a" and events_ahead >= 6  # its second write would reach apply_by

    # a's second write (6 events ahead) is held; a, b and c fill the 256 events
    assert take_batch(queue, holds) == [order[0], order[1], order[3]]
    assert ("a", 6) in asked
    assert list(queue) == [order[2], order[4], order[5]]  # the held one first, all in order
    assert take_batch(queue, lambda f, n: f == "a") == [order[4]]  # a's later one stays too
    assert list(queue) == [order[2], order[5]]
    assert take_batch(queue, lambda f, n: True) == []
    assert take_batch(queue) == [order[2], order[5]]
    assert not queue


def test_a_consolidation_due_in_another_process_s_events_is_applied_on_time(
    db_url: str, tmp_path: Path, make_client: Callable[..., TestClient]
) -> None:
    """Two services on one log, as two worker processes: the one that saw the
    consolidation fall due never finishes its solve; the other, catching up past
    ``apply_by`` from the log, hands it to its own solver and its first target waits."""
    saw_due, catches_up = make_client(db_url), make_client(db_url)
    never_answers, other = HandSolver(), HandSolver()
    saw_due.app.state.fleets.solver = never_answers  # type: ignore[attr-defined]
    catches_up.app.state.fleets.solver = other  # type: ignore[attr-defined]
    assert saw_due.post("/v1/fleets", json=spread_fleet_body("f")).status_code == 201
    assert catches_up.get("/v1/fleets/f").json()["version"] == 1  # in its memory, behind
    stream = hotspot_stream(APPLY_BY + 1)
    post_batches(saw_due, "f", stream[:APPLY_BY])
    [(job, _)] = never_answers.jobs  # due at the 250th target
    waiting, out = in_background(lambda: catches_up.post("/v1/fleets/f/targets", json=stream[-1]))
    deadline = time.monotonic() + 60
    while not other.jobs:  # the caught-up service hands the due solve to its solver
        assert time.monotonic() < deadline, "the caught-up service never asked for the solve"
        time.sleep(0.01)
    [(its_job, answer)] = other.jobs
    assert its_job.key == job.key and its_job.apply_by == APPLY_BY
    time.sleep(0.3)
    assert out == []  # its first target waits for the solve
    answer.set_result(its_job.solve())
    waiting.join(timeout=60)
    [r] = out
    assert r.status_code == 200, r.text
    assert r.json()["seq"] == APPLY_BY + 2 and "consolidated" in r.json()
    assert replay_ok(db_url, tmp_path)["ok"] is True
