"""Consolidations solved off the write path (the service's default), through HTTP.

A worker process solves the consolidation that the 250th target made due, on the
inputs of that moment; the first target after the solve finished applies it and
records it. Replay applies it there without solving; a restart while it is being
solved solves it again and applies it later.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Iterator
from concurrent.futures import Future
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient

from routing_svc.network import RoadSpace
from routing_svc.sa import Fleet, Objective, Vehicle, learning_config
from routing_svc.sa.consolidation import ConsolidationPolicy
from routing_svc.service.app import create_app
from routing_svc.service.background_solver import ConsolidationSolver, PendingConsolidation
from tests.helpers import (
    NET,
    LiveServer,
    hotspot_stream,
    make_settings,
    post_batches,
    replay_report,
    spread_fleet_body,
)

FIRST = ConsolidationPolicy().first
PATIENCE_S = 120.0
EXIT_GRACE_S = 5.0
"""How long a child process may take to notice that its service stopped cleanly."""


def start(db_url: str, tmp_path: Path) -> TestClient:
    client = TestClient(create_app(make_settings(db_url, tmp_path)))
    client.__enter__()
    return client


def post_until_consolidated(
    client: TestClient, fleet_id: str, targets: list[dict[str, Any]]
) -> tuple[dict[str, Any], int]:
    """Post ``targets`` one at a time, pausing, until a result records a consolidation;
    that result and how many were posted."""
    deadline = time.monotonic() + PATIENCE_S
    for k, body in enumerate(targets, start=1):
        r = client.post(f"/v1/fleets/{fleet_id}/targets", json=body)
        assert r.status_code == 200, r.text
        if "consolidated" in r.json():
            return r.json(), k
        assert time.monotonic() < deadline, "no consolidation was applied"
        time.sleep(0.05)
    raise AssertionError("no consolidation was applied")


def test_a_consolidation_solved_off_the_write_path_is_applied_later_and_replayed(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    sqlite_url = f"sqlite:///{tmp_path / 'events.db'}"
    targets = hotspot_stream(FIRST + 400)
    client = start(sqlite_url, tmp_path)
    try:
        assert client.app.state.fleets.solver is not None  # type: ignore[attr-defined]
        for fleet_id in ("steady", "restarted"):
            r = client.post("/v1/fleets", json=spread_fleet_body(fleet_id))
            assert r.status_code == 201, r.text
        head = post_batches(client, "steady", targets[:FIRST])
        # the 250th target (seq 251) made it due: none is solved inside a target
        assert not any("consolidated" in r for r in head)
        result, _ = post_until_consolidated(client, "steady", targets[FIRST:])
        assert result["seq"] > FIRST + 1
        record = result["consolidated"]
        # solved on the reservoir of the moment it fell due
        assert record["sample"] == FIRST
        assert len(record["positions"]) == len(record["updates"]) == 4
        if record["accepted"]:  # the step came first: the references are the record's
            fleet = client.get("/v1/fleets/steady").json()
            assert [
                (v["position"]["edge"], v["position"]["offset"]) for v in fleet["vehicles"]
            ] == [(p["edge"], p["offset"]) for p in record["positions"]]
        # a restart while the consolidation is being solved: it is solved again
        post_batches(client, "restarted", targets[:FIRST])
    finally:
        client.__exit__(None, None, None)
    client = start(sqlite_url, tmp_path)
    try:
        again, _ = post_until_consolidated(client, "restarted", targets[FIRST:])
        assert again["consolidated"]["sample"] >= FIRST
    finally:
        client.__exit__(None, None, None)

    def no_solving(*args: object, **kwargs: object) -> None:
        raise AssertionError("replay solved a consolidation")

    monkeypatch.setattr("routing_svc.sa.consolidation.consolidate", no_solving)
    report = replay_report(sqlite_url, tmp_path, capsys)
    assert report["ok"] is True
    assert {f["fleet"] for f in report["fleets"] if f["ok"]} == {"steady", "restarted"}


def test_a_batch_past_the_epoch_s_first_consolidation_applies_it(tmp_path: Path) -> None:
    """A new fleet's first consolidation, solved by the worker process, is applied by the
    target after it fell due, inside the batch that made it due: a batch of a few
    hundred targets does not leave the fleet where it started."""
    client = start(f"sqlite:///{tmp_path / 'events.db'}", tmp_path)
    try:
        assert client.post("/v1/fleets", json=spread_fleet_body("new")).status_code == 201
        r = client.post(
            "/v1/fleets/new/targets:batch", json={"targets": hotspot_stream(FIRST + 50)}
        )
        assert r.status_code == 200, r.text
        results = r.json()["results"]
        assert [k for k, x in enumerate(results) if "consolidated" in x] == [FIRST]
        record = results[FIRST]["consolidated"]
        assert record["sample"] == FIRST and record["accepted"] is True
        fleet = client.get("/v1/fleets/new").json()
        positions = [(p["edge"], p["offset"]) for p in record["positions"]]
        assert len(set(positions)) > 1
        # moved only by the held steps of the 49 targets after it
        kept = sum(
            (v["position"]["edge"], v["position"]["offset"]) == q
            for v, q in zip(fleet["vehicles"], positions, strict=True)
        )
        assert kept >= len(positions) - 49
        replayed = client.app.state.fleets.verify("new")  # type: ignore[attr-defined]
        assert replayed["version"] == fleet["version"] == FIRST + 51
    finally:
        client.__exit__(None, None, None)


def test_a_consolidating_fleet_stores_its_larger_snapshot_less_often(tmp_path: Path) -> None:
    client = start(f"sqlite:///{tmp_path / 'events.db'}", tmp_path)
    try:
        for fleet_id, rule in (("held", "consolidating"), ("small", "probe")):
            r = client.post("/v1/fleets", json=spread_fleet_body(fleet_id, rule=rule))
            assert r.status_code == 201, r.text
        targets = hotspot_stream(600)
        log = client.app.state.fleets.log  # type: ignore[attr-defined]
        seen: dict[str, set[int | None]] = {"held": set(), "small": set()}
        for start_at in range(0, 600, 25):
            for fleet_id in seen:
                r = client.post(
                    f"/v1/fleets/{fleet_id}/targets:batch",
                    json={"targets": targets[start_at : start_at + 25]},
                )
                assert r.status_code == 200, r.text
                seen[fleet_id].add(log.get_fleet(fleet_id).snapshot_version)
        # versions 26, 51, ...: a snapshot where a batch crossed a multiple of the cadence
        assert seen["small"] == {None, *(v for v in range(76, 602, 25) if v % 64 < 25)}
        assert seen["held"] == {None, 526}
        report = client.app.state.fleets.verify("held")  # type: ignore[attr-defined]
        assert report["snapshot_identical"] is True
    finally:
        client.__exit__(None, None, None)


def test_a_solve_that_failed_in_its_worker_is_solved_on_the_write_path() -> None:
    space = RoadSpace(NET)
    config = learning_config(
        "consolidating", typical_cost=space.typical_cost(), n_vehicles=3, objective=Objective(1.0)
    )
    starts = [space.decode(t["position"]) for t in hotspot_stream(3)]
    fleet = Fleet.create(space, [(Vehicle(f"v{i}"), p) for i, p in enumerate(starts)], config)
    fleet.defer_consolidations = True
    stream = [space.decode(body["position"]) for body in hotspot_stream(4 * FIRST)]
    for target in stream[:FIRST]:
        fleet.observe(target)
    first = fleet.consolidation_job()
    # due at the 250th target, the epoch's first: the next target applies it
    assert first is not None and first.key == (0, 0, FIRST) and first.apply_by == FIRST
    fleet.observe(stream[FIRST], solved=(first.key, first.solve()))
    for target in stream[FIRST + 1 :]:
        if fleet.due_consolidation() is not None:
            break
        fleet.observe(target)
    job = fleet.consolidation_job()
    assert job is not None and job.key[2] == fleet.state.targets
    # the next ones: applied by the end of the period after them at the latest
    assert job.apply_by == job.key[2] + FIRST
    answer: Future[Any] = Future()
    pending = PendingConsolidation(job, answer)
    assert pending.solved(job.apply_by - 1) is None  # not finished, not late: the target goes on
    answer.set_exception(RuntimeError("the worker died"))
    assert pending.solved(job.apply_by - 1) == (job.key, job.solve())
    # once late, a target waits for the answer
    later: Future[Any] = Future()
    done = job.solve()
    threading.Timer(0.3, later.set_result, args=(done,)).start()
    assert PendingConsolidation(job, later).solved(job.apply_by) == (job.key, done)


def children(pid: int) -> list[int]:
    """The live processes whose parent is ``pid`` (from ``/proc``)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            found.append(int(stat.parent.name))
    return found


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@contextmanager
def solving(tmp_path: Path) -> Iterator[tuple[LiveServer, list[int]]]:
    """A live server whose fleet just made its first consolidation due, and the worker
    processes solving it; whatever is left of both is killed afterwards."""
    server = LiveServer(f"sqlite:///{tmp_path / 'events.db'}", tmp_path).start()
    assert server.process is not None
    workers: list[int] = []
    try:
        httpx.post(server.url + "/v1/fleets", json=spread_fleet_body("f")).raise_for_status()
        body = {"targets": hotspot_stream(FIRST + 10)}
        httpx.post(server.url + "/v1/fleets/f/targets:batch", json=body, timeout=60)
        deadline = time.monotonic() + PATIENCE_S
        while not (found := children(server.process.pid)):  # the solver started
            assert time.monotonic() < deadline, "no worker process started"
            time.sleep(0.1)
        workers.extend(found)
        yield server, workers
    finally:
        for w in workers:
            if alive(w):
                os.kill(w, signal.SIGKILL)
        server.stop()


def test_no_worker_outlives_its_service_process(tmp_path: Path) -> None:
    with solving(tmp_path) as (server, workers):
        assert server.process is not None
        os.kill(server.process.pid, signal.SIGKILL)  # the service only, not its group
        server.process.wait(timeout=60)
        assert gone(workers, within_s=PATIENCE_S), "a worker outlived its service"


def test_a_signal_to_the_service_group_stops_it_cleanly_with_a_solve_in_flight(
    tmp_path: Path,
) -> None:
    with solving(tmp_path) as (server, workers):
        server.stop()  # SIGTERM to the process group, as Ctrl-C or `timeout` sends it
        assert "failed in its worker" not in server.log.read_text()
        # the pool's workers are joined on shutdown; multiprocessing's resource tracker,
        # also a child, leaves once the service's end of its pipe closes
        assert gone(workers, within_s=EXIT_GRACE_S)


def gone(pids: list[int], *, within_s: float) -> bool:
    """Whether every process of ``pids`` has ended within ``within_s`` seconds."""
    deadline = time.monotonic() + within_s
    while any(alive(p) for p in pids):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def test_started_workers_have_loaded_the_solver() -> None:
    solver = ConsolidationSolver(2)
    try:
        ready = solver.start()
        assert [f.result(timeout=PATIENCE_S) for f in ready] == [True, True]
    finally:
        solver.close()


def test_closing_waits_for_workers_that_finished_loading() -> None:
    """Idle workers are stopped before ``close`` returns, so the pool releases its queues
    (a pool left to stop on its own warns of leaked semaphores when the process ends)."""
    before = set(multiprocessing.active_children())
    solver = ConsolidationSolver(2)
    try:
        assert [f.result(timeout=PATIENCE_S) for f in solver.start()] == [True, True]
        workers = [w for w in multiprocessing.active_children() if w not in before]
        assert len(workers) == 2
    finally:
        solver.close()
    assert [w for w in workers if w.is_alive()] == []


def test_the_workers_start_with_the_service(tmp_path: Path) -> None:
    """Before any fleet has a consolidation due, the service's worker is running, so that
    the first solve does not wait for a process to start."""
    server = LiveServer(f"sqlite:///{tmp_path / 'events.db'}", tmp_path).start()
    assert server.process is not None
    try:
        deadline = time.monotonic() + PATIENCE_S
        while not children(server.process.pid):
            assert time.monotonic() < deadline, "no worker process started with the service"
            time.sleep(0.1)
    finally:
        server.stop()
