"""The committer thread: commits run one at a time, in the order they were handed over,
each outcome reaches its loop's future, and the hand-over waits until the thread started."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable, Iterator

import pytest

from routing_svc.service.write_path import committer as committer_module
from routing_svc.service.write_path.committer import COMMIT_HANDOFF_WAIT, Committer
from tests.helpers import blocked_until, handoff_timeouts, run


@pytest.fixture
def committer() -> Iterator[Committer]:
    opened = Committer("test-commit")
    yield opened
    opened.close()


def test_commits_run_in_order_on_the_thread_and_answer_on_the_loop(
    committer: Committer,
) -> None:
    ran: list[tuple[int, str]] = []

    def commit(number: int) -> Callable[[], None]:
        return lambda: ran.append((number, threading.current_thread().name))

    async def hand_over_all() -> None:
        loop = asyncio.get_running_loop()
        futures = [committer.hand_over(loop, commit(n)) for n in range(20)]
        assert await asyncio.gather(*futures) == [None] * 20

    run(hand_over_all())
    assert ran == [(n, "test-commit") for n in range(20)]
    assert committer.thread_name == "test-commit"


def test_the_hand_over_returns_once_the_thread_has_taken_the_commit(
    committer: Committer, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a wait that a loaded machine cannot outlast: what is checked is that the hand-over
    # returns after the thread took the commit and before the commit finished
    monkeypatch.setattr(committer_module, "COMMIT_HANDOFF_WAIT", 60.0)
    release = threading.Event()
    before = handoff_timeouts()

    async def hand_over() -> tuple[bool, bool]:
        loop = asyncio.get_running_loop()
        done = committer.hand_over(loop, blocked_until(release))
        taken = committer.waiting == 0  # the thread took it before the loop went on
        finished_early = done.done()
        release.set()
        await done
        return taken, finished_early

    taken, finished_early = run(hand_over())
    assert taken and not finished_early
    assert handoff_timeouts() == before


def test_a_busy_thread_costs_the_loop_only_the_bounded_wait(committer: Committer) -> None:
    release = threading.Event()
    order: list[str] = []
    before: list[float] = []

    async def hand_over() -> float:
        loop = asyncio.get_running_loop()
        busy = committer.hand_over(loop, blocked_until(release))
        # on a loaded machine the thread may take the first commit after its bound too
        before.append(handoff_timeouts())
        start = loop.time()
        second = committer.hand_over(loop, lambda: order.append("second"))
        waited = loop.time() - start
        assert not second.done() and order == []  # queued behind the busy one
        release.set()
        await asyncio.gather(busy, second)
        return waited

    waited = run(hand_over())
    assert order == ["second"]
    assert handoff_timeouts() == before[0] + 1  # the second hand-over's bounded wait
    assert waited >= COMMIT_HANDOFF_WAIT * 0.9  # it did wait for the bound, then went on


def test_a_failed_commit_fails_its_future_only(committer: Committer) -> None:
    class DiskFull(Exception):
        pass

    def failing() -> None:
        raise DiskFull("no space left")

    async def hand_over() -> tuple[BaseException | None, BaseException | None]:
        loop = asyncio.get_running_loop()
        bad = committer.hand_over(loop, failing)
        good = committer.hand_over(loop, lambda: None)
        return await asyncio.gather(bad, good, return_exceptions=True)

    error, fine = run(hand_over())
    assert isinstance(error, DiskFull) and fine is None


def test_a_cancelled_waiter_leaves_the_commit_running_and_the_loop_quiet(
    committer: Committer,
) -> None:
    release = threading.Event()
    ran: list[str] = []

    def slow() -> None:
        release.wait()
        ran.append("slow")

    async def hand_over() -> None:
        loop = asyncio.get_running_loop()
        done = committer.hand_over(loop, slow)
        done.cancel()  # the waiter went away; the commit still runs
        release.set()
        await committer.hand_over(loop, lambda: ran.append("next"))

    run(hand_over())
    assert ran == ["slow", "next"]


def test_close_runs_what_was_handed_over_then_stops_the_thread() -> None:
    committer = Committer("test-close")
    ran: list[int] = []
    release = threading.Event()

    async def hand_over() -> None:
        loop = asyncio.get_running_loop()
        committer.hand_over(loop, blocked_until(release))
        committer.hand_over(loop, lambda: ran.append(1))
        release.set()
        committer.close()  # (the loop's futures are set after, on the loop)
        assert ran == [1]
        assert not any(t.name == "test-close" for t in threading.enumerate())

    run(hand_over())
