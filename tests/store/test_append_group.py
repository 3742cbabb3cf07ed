"""EventLog.append_group: several requests in one transaction, on both backends."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import sqlalchemy as sa

from routing_svc.errors import Conflict, InvalidInput, RoutingSvcError, UnknownFleet, Unreachable
from routing_svc.store import (
    EventLog,
    EventRecord,
    FleetGroup,
    GroupItem,
    NewEvent,
    open_event_log,
)
from tests.helpers import append_group, append_one, one_each, target_event

SHA = "ab" * 32


@pytest.fixture
def log(db_url: str) -> Iterator[EventLog]:
    with open_event_log(db_url) as opened:
        opened.create_network("grid", sha256=SHA, path="/nets/grid.net.xml", name="grid")
        opened.create_fleet("f", "grid", "{}", "{}")
        yield opened


def stored_view(item: GroupItem) -> list[tuple[int, str, str, str | None, str | None]]:
    return [(e.seq, e.kind, e.payload_json, e.result_json, e.idempotency_key) for e in item.events]


def test_mixed_group_in_one_transaction(log: EventLog) -> None:
    known = append_one(
        log,
        "f",
        expected_version=1,
        build=lambda m: [target_event(1), target_event(2)],
        idempotency_key="old",
        request_hash="h-old",
    )
    calls: list[tuple[list[int], list[int]]] = []

    def build(
        missed: list[EventRecord], fresh: list[int]
    ) -> list[list[NewEvent] | RoutingSvcError]:
        calls.append(([e.seq for e in missed], list(fresh)))
        return [
            [target_event(10)],  # 0: fresh, keyed
            Unreachable("nobody reaches it"),  # 2: fails alone
            [target_event(30), target_event(31)],  # 3: fresh, two events
            [target_event(50)],  # 5: fresh, no key
        ]

    requests: list[tuple[str | None, str | None]] = [
        ("a", "h-a"),  # 0 fresh
        ("old", "h-old"),  # 1 duplicate of a stored batch
        ("c", "h-c"),  # 2 fails in build
        ("d", "h-d"),  # 3 fresh with two events
        ("old", "h-other"),  # 4 stored key, other request: Conflict
        (None, None),  # 5 fresh without key
        ("a", "h-a"),  # 6 repeats 0 within the group: duplicate
        ("d", "h-x"),  # 7 repeats 3 with another hash: Conflict
        ("c", "h-c"),  # 8 repeats 2, which failed: the same error
    ]
    items = append_group(log, "f", expected_version=1, requests=requests, build=build)
    assert calls == [([2, 3], [0, 2, 3, 5])]
    assert all(item.version == 7 for item in items)
    assert [e.seq for e in items[0].missed] == [2, 3]

    assert [(e.seq, e.idempotency_key) for e in items[0].events] == [(4, "a")]
    assert not items[0].duplicate and items[0].error is None
    assert items[1].duplicate and items[1].events == known.events
    assert isinstance(items[2].error, Unreachable) and items[2].events == ()
    assert [(e.seq, e.idempotency_key) for e in items[3].events] == [(5, "d"), (6, None)]
    assert isinstance(items[4].error, Conflict) and items[4].events == ()
    assert [(e.seq, e.idempotency_key) for e in items[5].events] == [(7, None)]
    assert items[6].duplicate and items[6].events == items[0].events
    assert isinstance(items[7].error, Conflict)
    assert items[8].error is items[2].error

    stored = log.events_since("f", 0)
    assert [e.seq for e in stored] == list(range(1, 8))  # contiguous, nothing of "c"
    assert [e.request_hash for e in stored[3:]] == ["h-a", "h-d", None, None]
    assert log.get_fleet("f").version == 7
    assert log.integrity_check() == []

    # a retry of any member later returns byte-identical stored results
    def never(missed: list[EventRecord], fresh: list[int]) -> list[list[NewEvent]]:
        raise AssertionError("build must not run when every request is known")

    retry = append_group(
        log,
        "f",
        expected_version=7,
        requests=[("a", "h-a"), ("d", "h-d"), ("old", "h-old")],
        build=never,
    )
    assert [r.duplicate for r in retry] == [True, True, True]
    for again, first in zip(retry, [items[0], items[3], items[1]], strict=True):
        assert again.events == first.events
        assert stored_view(again) == stored_view(first)
    single = append_one(
        log, "f", expected_version=7, build=lambda m: [], idempotency_key="d", request_hash="h-d"
    )
    assert single.duplicate and single.events == items[3].events
    # the failed request's key was not consumed
    later = append_group(
        log,
        "f",
        expected_version=7,
        requests=[("c", "h-c")],
        build=lambda m, f: [[target_event(8)]],
    )
    assert [e.seq for e in later[0].events] == [8] and not later[0].duplicate


def test_snapshot_is_taken_once_at_the_group_version(log: EventLog) -> None:
    seen: list[int] = []

    def snapshot(version: int) -> str:
        seen.append(version)
        return f'{{"at": {version}}}'

    append_group(
        log,
        "f",
        expected_version=1,
        requests=[(None, None), (None, None)],
        build=lambda m, f: [[target_event(1)], [target_event(2), target_event(3)]],
        snapshot=snapshot,
    )
    assert seen == [4]
    fleet = log.get_fleet("f")
    assert (fleet.snapshot_version, fleet.state_json) == (4, '{"at": 4}')


def test_failing_build_writes_nothing(log: EventLog) -> None:
    def build(missed: list[EventRecord], fresh: list[int]) -> list[list[NewEvent]]:
        raise ZeroDivisionError("bug")

    with pytest.raises(ZeroDivisionError):
        append_group(
            log, "f", expected_version=1, requests=[("k1", "h"), (None, None)], build=build
        )
    with pytest.raises(InvalidInput, match="entries"):
        append_group(
            log, "f", expected_version=1, requests=[("k1", "h"), (None, None)],
            build=lambda m, f: [[target_event(1)]],
        )  # fmt: skip
    bad: list[list[NewEvent]] = [["nope"]]  # type: ignore[list-item]
    with pytest.raises(InvalidInput):
        append_group(log, "f", expected_version=1, requests=[(None, None)], build=lambda m, f: bad)
    assert log.get_fleet("f").version == 1
    assert len(log.events_since("f", 0)) == 1
    # the keys were not consumed
    items = append_group(
        log, "f", expected_version=1, requests=[("k1", "h")], build=lambda m, f: [[target_event(1)]]
    )
    assert not items[0].duplicate and items[0].version == 2


def test_group_checks_the_cache_version_and_keys(log: EventLog) -> None:
    with pytest.raises(Conflict, match="version 1"):
        append_group(log, "f", expected_version=5, requests=[(None, None)], build=lambda m, f: [])
    with pytest.raises(InvalidInput):
        append_group(
            log,
            "f",
            expected_version=1,
            requests=[("", None)],
            build=lambda m, f: [[target_event(1)]],
        )
    assert log.get_fleet("f").version == 1


def test_groups_of_several_fleets_commit_together(log: EventLog) -> None:
    log.create_fleet("g", "grid", "{}", "{}")
    commits: list[int] = []
    sa.event.listen(log.engine, "commit", lambda conn: commits.append(1))
    results = log.append_groups(
        [
            FleetGroup("f", 1, (("k", "h"), (None, None)), one_each),
            FleetGroup("g", 1, ((None, None),), one_each),
        ]
    )
    assert len(commits) == 1
    assert [[e.seq for item in items for e in item.events] for items in results] == [[2, 3], [2]]
    assert log.get_fleet("f").version == 3
    assert log.get_fleet("g").version == 2
    assert [e.idempotency_key for e in log.events_since("f", 1)] == ["k", None]


def test_one_failing_fleet_writes_nothing_for_any(log: EventLog) -> None:
    log.create_fleet("g", "grid", "{}", "{}")
    log.delete_fleet("g")
    with pytest.raises(UnknownFleet):
        log.append_groups(
            [
                FleetGroup("f", 1, ((None, None),), one_each),
                FleetGroup("g", 2, ((None, None),), one_each),
            ]
        )
    assert log.get_fleet("f").version == 1
    assert log.events_since("f", 1) == []


def test_groups_name_each_fleet_once(log: EventLog) -> None:
    with pytest.raises(InvalidInput, match="one group per fleet"):
        log.append_groups(
            [FleetGroup("f", 1, ((None, None),), one_each)] * 2,
        )
    assert log.get_fleet("f").version == 1
