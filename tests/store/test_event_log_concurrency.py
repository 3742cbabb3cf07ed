"""Several threads and processes appending to one fleet, and a writer killed mid-way."""

from __future__ import annotations

import contextlib
import json
import os
import random
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from routing_svc.store import EventLog, EventRecord, GroupItem, NewEvent, open_event_log
from tests.helpers import append_one

BuildFn = Callable[[list[EventRecord]], list[NewEvent]]
APPENDER = Path(__file__).with_name("appender_proc.py")


def new_fleet(url: str, fleet_id: str = "f") -> None:
    with open_event_log(url) as log:
        log.create_network("n", sha256="0" * 64, path="/p", name="n")
        log.create_fleet(fleet_id, "n", "{}", "{}")


def assert_log_is_a_counter(log: EventLog, fleet_id: str, *, targets: int) -> list[EventRecord]:
    """Events 1..version, each target's result counting the targets before it."""
    stored = log.events_since(fleet_id, 0)
    assert [e.seq for e in stored] == list(range(1, targets + 2))
    counts = [json.loads(e.result_json or "null")["count"] for e in stored[1:]]
    assert counts == list(range(1, targets + 1))
    assert log.get_fleet(fleet_id).version == targets + 1
    assert log.integrity_check() == []
    return stored


def run_threads(workers: list[Callable[[], None]]) -> list[BaseException]:
    errors: list[BaseException] = []

    def guarded(work: Callable[[], None]) -> None:
        try:
            work()
        except BaseException as error:  # collected and asserted by the caller
            errors.append(error)

    threads = [threading.Thread(target=guarded, args=(work,)) for work in workers]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return errors


def counting_build(cache: dict[str, int], payload: str) -> BuildFn:
    def build(missed: list[EventRecord]) -> list[NewEvent]:
        assert [e.seq for e in missed] == list(
            range(cache["version"] + 1, cache["version"] + 1 + len(missed))
        )
        seen = cache["targets"] + sum(e.kind == "target" for e in missed)
        return [NewEvent("target", payload, json.dumps({"count": seen + 1}))]

    return build


def failing_build(build: BuildFn, *, fail: bool) -> BuildFn:
    """``build``, or a build that computes the same events and then raises."""

    def maybe_failing(missed: list[EventRecord]) -> list[NewEvent]:
        new = build(missed)
        if fail:
            raise ValueError("replay rejected")
        return new

    return maybe_failing


def catch_up(cache: dict[str, int], result: GroupItem) -> None:
    for event in result.missed + result.events:
        if event.seq == cache["version"] + 1:
            cache["version"] = event.seq
            cache["targets"] += event.kind == "target"


@pytest.mark.parametrize("shared_log", [True, False], ids=["one-log", "log-per-thread"])
def test_threads_append_in_one_order(db_url: str, *, shared_log: bool) -> None:
    new_fleet(db_url)
    threads, per_thread = 6, 12
    shared = open_event_log(db_url) if shared_log else None

    def worker(w: int) -> Callable[[], None]:
        def work() -> None:
            log = shared or open_event_log(db_url)
            cache = {"version": 1, "targets": 0}
            try:
                for i in range(per_thread):
                    payload = json.dumps({"w": w, "i": i})
                    catch_up(
                        cache,
                        append_one(
                            log,
                            "f",
                            expected_version=cache["version"],
                            build=counting_build(cache, payload),
                        ),
                    )
            finally:
                if shared is None:
                    log.close()

        return work

    try:
        assert run_threads([worker(w) for w in range(threads)]) == []
    finally:
        if shared is not None:
            shared.close()
    with open_event_log(db_url) as log:
        stored = assert_log_is_a_counter(log, "f", targets=threads * per_thread)
    payloads = {e.payload_json for e in stored[1:]}
    assert len(payloads) == threads * per_thread


def test_concurrent_retries_apply_once(db_url: str) -> None:
    new_fleet(db_url)
    results: list[GroupItem] = []
    built = []

    def build(missed: list[EventRecord]) -> list[NewEvent]:
        built.append(1)
        return [NewEvent("target", '{"t": 1}', '{"count": 1}'), NewEvent("note", "{}", "{}")]

    with open_event_log(db_url) as log:

        def retry() -> None:
            results.append(
                append_one(
                    log,
                    "f",
                    expected_version=1,
                    build=build,
                    idempotency_key="same",
                    request_hash="h",
                )
            )

        assert run_threads([retry] * 8) == []
        assert len(built) == 1
        assert sum(not r.duplicate for r in results) == 1
        assert {tuple(e.seq for e in r.events) for r in results} == {(2, 3)}
        assert len({r.events for r in results}) == 1
        assert log.get_fleet("f").version == 3


def test_failing_builds_among_threads_leave_no_trace(db_url: str) -> None:
    new_fleet(db_url)
    rng = random.Random(11)
    plan = [rng.random() < 0.4 for _ in range(40)]  # which appends fail

    with open_event_log(db_url) as log:

        def work(chunk: list[bool]) -> Callable[[], None]:
            def run() -> None:
                cache = {"version": 1, "targets": 0}
                for fail in chunk:
                    build = failing_build(counting_build(cache, "{}"), fail=fail)
                    with contextlib.suppress(ValueError):
                        result = append_one(
                            log, "f", expected_version=cache["version"], build=build
                        )
                        catch_up(cache, result)

            return run

        assert run_threads([work(plan[k::4]) for k in range(4)]) == []
        assert_log_is_a_counter(log, "f", targets=plan.count(False))


def test_processes_append_in_one_order(db_url: str) -> None:
    new_fleet(db_url)
    workers, per_worker = 3, 12
    procs = [
        subprocess.Popen(
            [sys.executable, str(APPENDER), "race", db_url, "f", f"p{w}", str(per_worker)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for w in range(workers)
    ]
    outcomes = [(proc.wait(timeout=120), proc.communicate()[1]) for proc in procs]
    assert [code for code, _ in outcomes] == [0] * workers, outcomes
    assert not any("locked" in err for _, err in outcomes)
    with open_event_log(db_url) as log:
        stored = assert_log_is_a_counter(log, "f", targets=workers * per_worker)
    keys = [str(e.idempotency_key) for e in stored[1:]]
    assert sorted(keys) == sorted(f"p{w}-{i}" for w in range(workers) for i in range(per_worker))


def test_killed_writer_loses_no_acknowledged_event(db_url: str) -> None:
    new_fleet(db_url)
    proc = subprocess.Popen(
        [sys.executable, str(APPENDER), "crash", db_url, "f"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    acknowledged: list[int] = []
    try:
        assert proc.stdout is not None
        while len(acknowledged) < 40:
            line = proc.stdout.readline()
            assert line, proc.stderr.read() if proc.stderr else "writer died"
            acknowledged.append(int(line))
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stdout.close()  # type: ignore[union-attr]
        proc.stderr.close()  # type: ignore[union-attr]
    assert proc.returncode == -signal.SIGKILL
    with open_event_log(db_url) as log:
        assert log.integrity_check() == []
        version = log.get_fleet("f").version
        stored = log.events_since("f", 0)
    assert version >= acknowledged[-1]
    assert [e.seq for e in stored] == list(range(1, version + 1))
    for ack in acknowledged:  # each batch of two events is whole
        assert json.loads(stored[ack - 1].payload_json) == {"n": ack - 2}
        assert stored[ack - 2].payload_json == stored[ack - 1].payload_json
