"""Behaviour of the EventLog API on both backends (see conftest.db_url)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from routing_svc.errors import (
    Conflict,
    InvalidInput,
    StorageError,
    UnknownFleet,
    UnknownNetwork,
)
from routing_svc.store import (
    FLEET_CREATED,
    FLEET_DELETED,
    EventLog,
    EventRecord,
    NewEvent,
    open_event_log,
)
from tests.helpers import append_one

SHA = "ab" * 32


@pytest.fixture
def log(db_url: str) -> Iterator[EventLog]:
    with open_event_log(db_url) as opened:
        opened.create_network("grid", sha256=SHA, path="/nets/grid.net.xml", name="grid")
        yield opened


def target(n: int) -> NewEvent:
    return NewEvent("target", f'{{"n": {n}}}', f'{{"moved": {n}}}')


def test_constructor_does_no_io_and_closed_log_refuses(db_url: str) -> None:
    log = EventLog(db_url)
    with pytest.raises(StorageError, match="not open"):
        log.list_networks()
    log.close()  # closing a log that never opened is harmless


def test_networks_round_trip(log: EventLog) -> None:
    record = log.get_network("grid")
    assert (record.sha256, record.path, record.name, record.meta_json) == (
        SHA,
        "/nets/grid.net.xml",
        "grid",
        "{}",
    )
    assert record.created_at.tzinfo is not None
    log.create_network("drt", sha256="00" * 32, path="/x", name="DRT", meta_json='{"k": 1}')
    assert [n.id for n in log.list_networks()] == ["drt", "grid"]
    with pytest.raises(Conflict):
        log.create_network("grid", sha256=SHA, path="/y", name="again")
    with pytest.raises(UnknownNetwork):
        log.get_network("nope")


def test_create_fleet_writes_row_and_first_event(log: EventLog) -> None:
    fleet = log.create_fleet("taxis", "grid", '{"vehicles": 3}', '{"seed": 7}')
    assert (fleet.id, fleet.network_id, fleet.config_json, fleet.version) == (
        "taxis",
        "grid",
        '{"vehicles": 3}',
        1,
    )
    assert fleet.state_json is None and fleet.snapshot_version is None and not fleet.deleted
    [first] = log.events_since("taxis", 0)
    assert (first.seq, first.kind, first.payload_json, first.result_json) == (
        1,
        FLEET_CREATED,
        '{"seed": 7}',
        None,
    )
    with pytest.raises(Conflict):
        log.create_fleet("taxis", "grid", "{}", "{}")
    with pytest.raises(UnknownNetwork):
        log.create_fleet("other", "missing-net", "{}", "{}")
    assert [f.id for f in log.list_fleets()] == ["taxis"]
    assert log.list_fleets(network_id="elsewhere") == []


def test_append_numbers_a_batch_contiguously(log: EventLog) -> None:
    log.create_fleet("f", "grid", "{}", "{}")
    result = append_one(log, "f", expected_version=1, build=lambda missed: [target(1), target(2)])
    assert (result.version, result.duplicate, result.missed) == (3, False, ())
    assert [e.seq for e in result.events] == [2, 3]
    assert [e.payload_json for e in log.events_since("f", 1)] == ['{"n": 1}', '{"n": 2}']
    assert log.get_fleet("f").version == 3


def test_build_sees_the_events_the_caller_missed(log: EventLog) -> None:
    log.create_fleet("f", "grid", "{}", "{}")
    append_one(log, "f", expected_version=1, build=lambda missed: [target(1), target(2)])
    seen: list[list[EventRecord]] = []

    def build(missed: list[EventRecord]) -> list[NewEvent]:
        seen.append(missed)
        return [target(3)]

    result = append_one(log, "f", expected_version=1, build=build)
    assert [e.seq for e in seen[0]] == [2, 3]
    assert [e.seq for e in result.missed] == [2, 3]
    assert [e.seq for e in result.events] == [4]
    with pytest.raises(Conflict, match="version 4"):
        append_one(log, "f", expected_version=9, build=build)


def test_failing_build_writes_nothing(log: EventLog) -> None:
    log.create_fleet("f", "grid", "{}", "{}")

    def build(missed: list[EventRecord]) -> list[NewEvent]:
        raise ZeroDivisionError("replay failed")

    with pytest.raises(ZeroDivisionError):
        append_one(log, "f", expected_version=1, build=build, idempotency_key="k", request_hash="h")
    assert log.get_fleet("f").version == 1
    assert len(log.events_since("f", 0)) == 1
    # the key was not consumed: a retry with a working build applies once
    retry = append_one(
        log, "f", expected_version=1, build=lambda m: [target(1)], idempotency_key="k"
    )
    assert retry.version == 2 and not retry.duplicate


def test_bad_build_output_is_rejected_and_writes_nothing(log: EventLog) -> None:
    log.create_fleet("f", "grid", "{}", "{}")
    with pytest.raises(InvalidInput):
        append_one(log, "f", expected_version=1, build=lambda m: ["not an event"])  # type: ignore[list-item]
    with pytest.raises(InvalidInput):
        append_one(log, "f", expected_version=1, build=lambda m: [NewEvent("", "{}")])
    assert log.get_fleet("f").version == 1


def test_empty_build_is_a_no_op(log: EventLog) -> None:
    log.create_fleet("f", "grid", "{}", "{}")
    result = append_one(log, "f", expected_version=1, build=lambda m: [], idempotency_key="k")
    assert (result.version, result.events) == (1, ())
    again = append_one(
        log, "f", expected_version=1, build=lambda m: [target(1)], idempotency_key="k"
    )
    assert not again.duplicate and again.version == 2


def test_idempotent_retry_returns_stored_batch(log: EventLog) -> None:
    log.create_fleet("f", "grid", "{}", "{}")
    first = append_one(
        log,
        "f",
        expected_version=1,
        build=lambda m: [target(1), target(2)],
        idempotency_key="req-1",
        request_hash="h1",
    )
    append_one(log, "f", expected_version=3, build=lambda m: [target(3)])

    def never(missed: list[EventRecord]) -> list[NewEvent]:
        raise AssertionError("build must not run for a known key")

    retry = append_one(
        log, "f", expected_version=1, build=never, idempotency_key="req-1", request_hash="h1"
    )
    assert retry.duplicate
    assert retry.events == first.events
    assert [e.result_json for e in retry.events] == ['{"moved": 1}', '{"moved": 2}']
    assert retry.version == 4 and [e.seq for e in retry.missed] == [2, 3, 4]
    assert log.get_fleet("f").version == 4
    with pytest.raises(Conflict, match="another request"):
        append_one(
            log, "f", expected_version=4, build=never, idempotency_key="req-1", request_hash="h2"
        )
    # keys are per fleet
    log.create_fleet("g", "grid", "{}", "{}")
    other = append_one(
        log, "g", expected_version=1, build=lambda m: [target(9)], idempotency_key="req-1"
    )
    assert not other.duplicate


def test_json_text_is_kept_byte_for_byte(log: EventLog) -> None:
    odd = '{ "x": 0.30000000000000004,  "y": 1e-310, "s": "Zürich \\u00e9 \U0001f695" }'
    log.create_fleet("f", "grid", odd, odd)
    append_one(log, "f", expected_version=1, build=lambda m: [NewEvent("target", odd, odd)])
    assert log.get_fleet("f").config_json == odd
    stored = log.events_since("f", 0)
    assert {stored[0].payload_json, stored[1].payload_json, stored[1].result_json} == {odd}


def test_snapshots(log: EventLog) -> None:
    log.create_fleet("f", "grid", "{}", "{}")
    append_one(
        log,
        "f",
        expected_version=1,
        build=lambda m: [target(1), target(2)],
        snapshot=lambda version: f'{{"at": {version}}}',
    )
    fleet = log.get_fleet("f")
    assert (fleet.state_json, fleet.snapshot_version) == ('{"at": 3}', 3)
    append_one(log, "f", expected_version=3, build=lambda m: [target(3)], snapshot=lambda v: None)
    assert log.get_fleet("f").snapshot_version == 3
    assert log.save_snapshot("f", 4, '{"at": 4}')
    assert not log.save_snapshot("f", 2, '{"at": 2}')  # older than the stored one
    assert log.get_fleet("f").state_json == '{"at": 4}'
    with pytest.raises(Conflict):
        log.save_snapshot("f", 5, "{}")


def test_event_pages(log: EventLog) -> None:
    log.create_fleet("f", "grid", "{}", "{}")
    append_one(log, "f", expected_version=1, build=lambda m: [target(n) for n in range(9)])
    pages, after = [], 0
    while page := log.events("f", after=after, limit=4):
        pages.append([e.seq for e in page])
        after = page[-1].seq
    assert pages == [[1, 2, 3, 4], [5, 6, 7, 8], [9, 10]]
    assert [e.seq for e in log.events_since("f", 8)] == [9, 10]
    assert log.events_since("f", 10) == []
    with pytest.raises(InvalidInput):
        log.events("f", after=0, limit=0)
    with pytest.raises(InvalidInput):
        log.events_since("f", -1)
    with pytest.raises(UnknownFleet):
        log.events("nope")


def test_soft_delete(log: EventLog) -> None:
    log.create_fleet("f", "grid", "{}", "{}")
    gone = log.delete_fleet("f", payload_json='{"by": "test"}')
    assert (gone.seq, gone.kind, gone.payload_json) == (2, FLEET_DELETED, '{"by": "test"}')
    with pytest.raises(UnknownFleet):
        log.get_fleet("f")
    with pytest.raises(UnknownFleet):
        append_one(log, "f", expected_version=2, build=lambda m: [target(1)])
    with pytest.raises(UnknownFleet):
        log.delete_fleet("f")
    assert log.list_fleets() == []
    assert [f.id for f in log.list_fleets(include_deleted=True)] == ["f"]
    assert log.get_fleet("f", include_deleted=True).deleted
    assert [e.kind for e in log.events_since("f", 0)] == [FLEET_CREATED, FLEET_DELETED]
    with pytest.raises(Conflict, match="never reused"):
        log.create_fleet("f", "grid", "{}", "{}")


def test_unknown_fleet_and_bad_arguments(log: EventLog) -> None:
    with pytest.raises(UnknownFleet):
        append_one(log, "ghost", expected_version=0, build=lambda m: [target(1)])
    with pytest.raises(UnknownFleet):
        log.get_fleet("ghost")
    with pytest.raises(UnknownFleet):
        log.save_snapshot("ghost", 1, "{}")
    with pytest.raises(InvalidInput):
        log.create_fleet("", "grid", "{}", "{}")
    with pytest.raises(InvalidInput):
        log.create_fleet("x" * 129, "grid", "{}", "{}")
    log.create_fleet("f", "grid", "{}", "{}")
    with pytest.raises(InvalidInput):
        append_one(log, "f", expected_version=-1, build=lambda m: [])
    with pytest.raises(InvalidInput):
        append_one(log, "f", expected_version=1, build=lambda m: [], idempotency_key="")


def test_reopen_keeps_everything_and_integrity_holds(db_url: str) -> None:
    with open_event_log(db_url) as log:
        log.create_network("n", sha256=SHA, path="/p", name="n")
        log.create_fleet("f", "n", "{}", "{}")
        append_one(log, "f", expected_version=1, build=lambda m: [target(1)])
    with open_event_log(db_url) as log:  # migrations are already at head
        assert log.get_fleet("f").version == 2
        assert log.integrity_check() == []
