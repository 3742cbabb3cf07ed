"""A separate process that appends to one fleet (driven by the concurrency tests).

Usage::

    python appender_proc.py race URL FLEET WORKER COUNT
    python appender_proc.py crash URL FLEET

``race`` appends COUNT ``target`` events the way a service worker does
(:meth:`EventLog.append_groups`, one request a group): it keeps a cached count
of targets and its version, replays the events it missed inside ``build`` and
stores the count it computed as the event's result. Every
append is sent twice with the same idempotency key (a retry after a lost
answer). ``crash`` appends forever and prints each version after its commit,
so the parent can kill it and check that every acknowledged event survived.
"""

from __future__ import annotations

import json
import sys

from routing_svc.store import (
    BuildGroup,
    EventLog,
    EventRecord,
    FleetGroup,
    GroupItem,
    NewEvent,
    open_event_log,
)


class CachedFleet:
    """The in-memory state of one worker: targets applied and version."""

    def __init__(self) -> None:
        self.version = 1
        self.targets = 0

    def build_target(self, payload: dict[str, object]) -> BuildGroup:
        def build(missed: list[EventRecord], fresh: list[int]) -> list[list[NewEvent]]:
            seen = self.targets + sum(1 for e in missed if e.kind == "target")
            expected = list(range(self.version + 1, self.version + 1 + len(missed)))
            if [e.seq for e in missed] != expected:
                raise RuntimeError(f"missed events out of order: {[e.seq for e in missed]}")
            return [[NewEvent("target", json.dumps(payload), json.dumps({"count": seen + 1}))]]

        return build

    def catch_up(self, events: tuple[EventRecord, ...]) -> None:
        for event in events:
            if event.seq == self.version + 1:
                self.version = event.seq
                self.targets += event.kind == "target"


def race(url: str, fleet: str, worker: str, count: int) -> None:
    cache = CachedFleet()
    with open_event_log(url) as log:
        for i in range(count):
            key = f"{worker}-{i}"
            payload = {"worker": worker, "i": i}
            request = FleetGroup(fleet, cache.version, ((key, key),), cache.build_target(payload))
            first = append(log, request)
            retry = append(log, request)
            if not retry.duplicate or retry.events != first.events:
                raise RuntimeError(f"retry of {key} was applied again")
            cache.catch_up(first.missed + first.events)


def append(log: EventLog, request: FleetGroup) -> GroupItem:
    """Append a group of one request; its item."""
    ((item,),) = log.append_groups([request])
    if item.error is not None:
        raise item.error
    return item


def constant(batch: list[NewEvent]) -> BuildGroup:
    """A build that ignores the missed events (this writer is the only one)."""
    return lambda missed, fresh: [batch]


def crash(url: str, fleet: str) -> None:
    version = 1
    with open_event_log(url) as log:
        while True:
            payload = json.dumps({"n": version})
            batch = [NewEvent("target", payload), NewEvent("target", payload)]
            result = append(log, FleetGroup(fleet, version, ((None, None),), constant(batch)))
            version = result.version
            print(version, flush=True)


if __name__ == "__main__":
    mode, url, fleet_id, *rest = sys.argv[1:]
    if mode == "race":
        race(url, fleet_id, rest[0], int(rest[1]))
    else:
        crash(url, fleet_id)
