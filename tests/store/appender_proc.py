"""A separate process that appends to one fleet (driven by the concurrency tests).

Usage::

    python appender_proc.py race URL FLEET WORKER COUNT
    python appender_proc.py crash URL FLEET

``race`` appends COUNT ``target`` events the way a service worker does: it
keeps a cached count of targets and its version, replays the events it missed
inside ``build`` and stores the count it computed as the event's result. Every
append is sent twice with the same idempotency key (a retry after a lost
answer). ``crash`` appends forever and prints each version after its commit,
so the parent can kill it and check that every acknowledged event survived.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable

from routing_svc.store import EventRecord, NewEvent, open_event_log


class CachedFleet:
    """The in-memory state of one worker: targets applied and version."""

    def __init__(self) -> None:
        self.version = 1
        self.targets = 0

    def build_target(
        self, payload: dict[str, object]
    ) -> Callable[[list[EventRecord]], list[NewEvent]]:
        def build(missed: list[EventRecord]) -> list[NewEvent]:
            seen = self.targets + sum(1 for e in missed if e.kind == "target")
            expected = list(range(self.version + 1, self.version + 1 + len(missed)))
            if [e.seq for e in missed] != expected:
                raise RuntimeError(f"missed events out of order: {[e.seq for e in missed]}")
            return [NewEvent("target", json.dumps(payload), json.dumps({"count": seen + 1}))]

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
            first = log.append(
                fleet,
                expected_version=cache.version,
                build=cache.build_target(payload),
                idempotency_key=key,
                request_hash=key,
            )
            retry = log.append(
                fleet,
                expected_version=cache.version,
                build=cache.build_target(payload),
                idempotency_key=key,
                request_hash=key,
            )
            if not retry.duplicate or retry.events != first.events:
                raise RuntimeError(f"retry of {key} was applied again")
            cache.catch_up(first.missed + first.events)


def constant(batch: list[NewEvent]) -> Callable[[list[EventRecord]], list[NewEvent]]:
    """A build that ignores the missed events (this writer is the only one)."""
    return lambda missed: batch


def crash(url: str, fleet: str) -> None:
    version = 1
    with open_event_log(url) as log:
        while True:
            payload = json.dumps({"n": version})
            batch = [NewEvent("target", payload), NewEvent("target", payload)]
            result = log.append(fleet, expected_version=version, build=constant(batch))
            version = result.version
            print(version, flush=True)


if __name__ == "__main__":
    mode, url, fleet_id, *rest = sys.argv[1:]
    if mode == "race":
        race(url, fleet_id, rest[0], int(rest[1]))
    else:
        crash(url, fleet_id)
