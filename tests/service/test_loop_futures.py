"""Targets queued from an event loop are answered with that loop's own futures: on the
loop when it commits them, from the worker thread when it cannot, and a waiter that
goes away (a client that disconnected) changes nothing about what is written."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa

from routing_svc.service.inprocess import InProcessFleetClient
from routing_svc.service.schemas import TargetSpec
from routing_svc.service.write_path import Answer, PendingAnswer
from tests.helpers import DRT, blocked_until, fleet_body, handoff_timeouts, run, targets


@pytest.fixture
def client() -> Iterator[InProcessFleetClient]:
    with InProcessFleetClient() as opened:  # SQLite: the loop stages what it receives
        opened.add_network(Path(DRT), name="drt")
        opened.create_fleet(fleet_body("a"))
        yield opened


def specs(seed: int, n: int) -> list[TargetSpec]:
    return [TargetSpec.model_validate(t) for t in targets(seed, n)]


def on_loop(future: PendingAnswer) -> asyncio.Future[Answer]:
    """The future of a request queued from a loop: one of that loop's."""
    assert isinstance(future, asyncio.Future)
    return future


def test_answers_come_on_the_loops_own_futures(client: InProcessFleetClient) -> None:
    service = client.service

    async def post() -> list[int]:
        loop = asyncio.get_running_loop()
        futures = [on_loop(service.submit_targets("a", [t], loop=loop)) for t in specs(1, 6)]
        answers = await asyncio.gather(*futures)
        await service.drain()
        return [seq for _, seq in answers]

    assert run(post()) == [2, 3, 4, 5, 6, 7]
    assert client.get_fleet("a")["version"] == 7


def test_a_group_written_by_a_worker_thread_answers_on_the_loop(
    client: InProcessFleetClient,
) -> None:
    service = client.service
    lock = service.lock_of("a")

    async def post() -> list[int]:
        loop = asyncio.get_running_loop()
        lock.acquire()  # the loop cannot take the fleet's lock: a worker thread writes
        threading.Timer(0.3, lock.release).start()
        futures = [on_loop(service.submit_targets("a", [t], loop=loop)) for t in specs(2, 3)]
        answers = await asyncio.gather(*futures)
        await service.drain()
        return [seq for _, seq in answers]

    assert run(post()) == [2, 3, 4]


def test_a_waiter_that_went_away_still_gets_its_target_written_once(
    client: InProcessFleetClient,
) -> None:
    service = client.service

    async def post() -> None:
        loop = asyncio.get_running_loop()
        first, second, third = (
            on_loop(service.submit_targets("a", [t], loop=loop)) for t in specs(3, 3)
        )
        first.cancel()  # its client disconnected before the commit
        assert (await second)[1] == 3 and (await third)[1] == 4
        await service.drain()

    run(post())
    fleet = client.get_fleet("a")
    assert fleet["version"] == 4
    events = service.log.events("a")
    assert [e.seq for e in events] == [1, 2, 3, 4]
    assert [e.kind for e in events[1:]] == ["target"] * 3


def test_the_commit_runs_on_the_committer_thread_and_the_loop_serves_while_it_waits(
    client: InProcessFleetClient,
) -> None:
    """The loop hands the commit to the committer thread; if that thread cannot start it
    (here: busy until the test lets it go), the loop waits only for the bounded hand-over,
    goes on running its other callbacks, and the target is answered once it is durable."""
    service = client.service
    committer_threads: list[str] = []

    def commit_seen(conn: sa.engine.Connection) -> None:
        committer_threads.append(threading.current_thread().name)

    async def post() -> tuple[int, int, bool, bool]:
        loop = asyncio.get_running_loop()
        # a first target starts the committer thread; it commits there
        (_, first) = await on_loop(service.submit_targets("a", specs(5, 1), loop=loop))
        timeouts_before = handoff_timeouts()
        committer = service.group_commit.committer
        assert committer is not None
        release = threading.Event()
        # the committer is busy, so it cannot start the next commit
        busy = committer.hand_over(loop, blocked_until(release))
        future = on_loop(service.submit_targets("a", specs(6, 1), loop=loop))
        ran_meanwhile = asyncio.Event()
        loop.call_soon(ran_meanwhile.set)
        await ran_meanwhile.wait()  # the loop is not stuck behind the commit ...
        await asyncio.sleep(0.05)
        pending_while_busy = not future.done()  # ... which cannot be durable yet
        release.set()
        (_, second) = await future
        await busy
        await service.drain()
        # that hand-over timed out; on a loaded machine a later one may time out too
        timed_out = handoff_timeouts() - timeouts_before >= 1
        return first, second, pending_while_busy, timed_out

    sa.event.listen(service.log.engine, "commit", commit_seen)
    try:
        first, second, pending_while_busy, timed_out = run(post())
    finally:
        sa.event.remove(service.log.engine, "commit", commit_seen)
    assert (first, second) == (2, 3)
    assert pending_while_busy and timed_out
    assert committer_threads == ["routing-svc-commit"] * 2
    events = service.log.events("a")
    assert [e.seq for e in events] == [1, 2, 3]
    assert client.get_fleet("a")["version"] == 3
