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
"""The epoch's first consolidation falls due at target ``FIRST`` and is applied at once;
the ones after it by the end of the period that follows them."""


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


def second_due(
    client: TestClient, solver: HandSolver, fleet_id: str, stream: list[dict[str, Any]]
) -> tuple[ConsolidationJob[Any], Future[Any]]:
    """Post ``stream`` until the epoch's second consolidation falls due, answering the
    first (applied at once, by the target after it fell due); its job and answer."""
    seen = client.get(f"/v1/fleets/{fleet_id}").json()["targets"]
    post_batches(client, fleet_id, stream[seen:FIRST])
    [(first, answer)] = solver.jobs  # due at the 250th target, handed to the solver
    assert first.apply_by == FIRST  # the epoch's first: the next target waits for it
    answer.set_result(first.solve())
    for k, body in enumerate(stream[FIRST:], start=FIRST + 1):
        r = client.post(f"/v1/fleets/{fleet_id}/targets", json=body)
        assert r.status_code == 200, r.text
        assert ("consolidated" in r.json()) is (k == FIRST + 1)  # it applied the first
        if len(solver.jobs) == 2:
            job, later = solver.jobs[1]
            assert job.key[2] == k  # due at the k-th target
            assert job.apply_by > k  # applied by the period after it
            return job, later
    raise AssertionError("no second consolidation fell due")


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
    stream = hotspot_stream(4 * FIRST)
    job, answer = second_due(client, solver, "waits", stream)
    apply_by = job.apply_by
    post_batches(client, "waits", stream[job.key[2] : apply_by])  # up to apply_by: not held

    def post_one(body: dict[str, Any]) -> Any:
        if writer == "http":
            r = client.post("/v1/fleets/waits/targets", json=body)
            assert r.status_code == 200, r.text
            return r.json()
        results, _ = service.post_targets("waits", [TargetSpec.model_validate(body)])
        return json.loads(results[0])

    first, first_out = in_background(lambda: post_one(stream[apply_by]))
    time.sleep(0.3)
    second, second_out = in_background(lambda: post_one(stream[apply_by + 1]))
    time.sleep(0.5)
    assert first_out == [] and second_out == []  # held while the solve runs
    for body in hotspot_stream(20):  # the other fleet is written meanwhile
        r = client.post("/v1/fleets/other/targets", json=body)
        assert r.status_code == 200, r.text
    assert client.get("/v1/fleets/other").json()["version"] == 21
    assert client.get("/v1/fleets/waits").json()["version"] == 1 + apply_by
    assert first_out == [] and second_out == []

    answer.set_result(job.solve())
    first.join(timeout=60)
    second.join(timeout=60)
    [held_first], [held_second] = first_out, second_out
    assert (held_first["seq"], held_second["seq"]) == (apply_by + 2, apply_by + 3)  # in order
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
    stream = hotspot_stream(4 * FIRST)
    job, _ = second_due(saw_due, never_answers, "f", stream)
    apply_by = job.apply_by
    post_batches(saw_due, "f", stream[job.key[2] : apply_by])
    waiting, out = in_background(
        lambda: catches_up.post("/v1/fleets/f/targets", json=stream[apply_by])
    )
    deadline = time.monotonic() + 60
    while not other.jobs:  # the caught-up service hands the due solve to its solver
        assert time.monotonic() < deadline, "the caught-up service never asked for the solve"
        time.sleep(0.01)
    [(its_job, answer)] = other.jobs
    assert its_job.key == job.key and its_job.apply_by == apply_by
    time.sleep(0.3)
    assert out == []  # its first target waits for the solve
    answer.set_result(its_job.solve())
    waiting.join(timeout=60)
    [r] = out
    assert r.status_code == 200, r.text
    assert r.json()["seq"] == apply_by + 2 and "consolidated" in r.json()
    assert replay_ok(db_url, tmp_path)["ok"] is True


def test_a_batch_that_reaches_a_due_consolidation_waits_off_the_event_loop(
    db_url: str, make_client: Callable[..., TestClient]
) -> None:
    """A batch whose targets pass the epoch's first consolidation, due and applied at once,
    waits for its solve on a worker thread: the event loop answers reads meanwhile, and
    the writes queued behind the batch follow it."""
    client = make_client(db_url)
    solver = HandSolver()
    client.app.state.fleets.solver = solver  # type: ignore[attr-defined]
    for fleet_id in ("crosses", "other"):
        assert client.post("/v1/fleets", json=spread_fleet_body(fleet_id)).status_code == 201
    batch = {"targets": hotspot_stream(FIRST + 10)}
    crossing, crossing_out = in_background(
        lambda: client.post("/v1/fleets/crosses/targets:batch", json=batch)
    )
    deadline = time.monotonic() + 60
    while not solver.jobs:  # the 250th target made it due
        assert time.monotonic() < deadline, "the consolidation never fell due"
        time.sleep(0.01)
    [(job, answer)] = solver.jobs
    assert job.apply_by == FIRST
    try:
        reads, reads_out = in_background(lambda: client.get("/v1/fleets/other"))
        reads.join(timeout=10)
        assert [r.json()["version"] for r in reads_out] == [1]  # answered while it waits
        writes, writes_out = in_background(
            lambda: client.post("/v1/fleets/other/targets", json=hotspot_stream(1)[0])
        )
        assert crossing_out == []
    finally:
        answer.set_result(job.solve())
    crossing.join(timeout=60)
    writes.join(timeout=60)
    assert [w.status_code for w in writes_out] == [200]
    [r] = crossing_out
    assert r.status_code == 200, r.text
    results = r.json()["results"]
    assert [k for k, x in enumerate(results) if "consolidated" in x] == [FIRST]


def test_a_fleet_shows_its_next_consolidation(
    db_url: str, make_client: Callable[..., TestClient]
) -> None:
    client = make_client(db_url)
    solver = HandSolver()
    client.app.state.fleets.solver = solver  # type: ignore[attr-defined]
    assert client.post("/v1/fleets", json=spread_fleet_body("f")).status_code == 201
    probe = spread_fleet_body("p", rule="probe")
    assert client.post("/v1/fleets", json=probe).status_code == 201

    def view(fleet_id: str) -> Any:
        r = client.get(f"/v1/fleets/{fleet_id}")
        assert r.status_code == 200, r.text
        return r.json()["consolidation"]

    assert view("p") is None  # the probe rule does not consolidate
    assert view("f") == {"due_at": FIRST, "apply_by": FIRST}
    stream = hotspot_stream(4 * FIRST)
    post_batches(client, "f", stream[:FIRST])
    assert view("f") == {"due_at": FIRST, "apply_by": FIRST}  # due, being solved
    job, answer = second_due(client, solver, "f", stream)  # answers the first on its way
    assert view("f") == {"due_at": job.key[2], "apply_by": job.apply_by}
    answer.set_result(job.solve())
    assert view("f") == {"due_at": job.key[2], "apply_by": job.apply_by}  # until applied
