"""Staging of group commits: the rows and versions of several requests, in one transaction.

A :class:`FleetGroup` is one fleet's share of an append: its requests
(idempotency key and request hash each), the ``build`` callback that computes
their events and the ``snapshot`` callback. :func:`write_groups` stages every
fleet's group inside an open write transaction and writes their rows and new
versions; the caller commits. :class:`~routing_svc.store.event_log.EventLog`
runs it in :meth:`~routing_svc.store.event_log.EventLog.append_groups` and
:meth:`~routing_svc.store.event_log.EventLog.try_append_groups_uncommitted`.

Per fleet, in order (:func:`stage_group`):

1. a known idempotency key answers its request from the log (a duplicate, or
   :class:`~routing_svc.errors.Conflict` when its request hash differs); a key
   repeated within the group is a duplicate of its first occurrence;
2. the events other writers stored after the caller's version (``missed``) and
   the indices of the fresh requests go to ``build``, which returns one entry per
   fresh request: its events, or the domain error that fails it alone;
3. the events are numbered contiguously after the locked version, and
   ``snapshot(new_version)`` may give a state to store with the new version.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy.engine import Connection

from routing_svc.errors import Conflict, InvalidInput, RoutingSvcError
from routing_svc.store import queries as q
from routing_svc.store.records import EventRecord, GroupItem, NewEvent

__all__ = [
    "BuildGroup",
    "FleetGroup",
    "Snapshot",
    "StagedGroup",
    "check_groups",
    "stage_group",
    "write_groups",
]

BuildGroup = Callable[
    [list[EventRecord], list[int]], Sequence[Sequence[NewEvent] | RoutingSvcError]
]
"""``build(missed_events, fresh_indices) -> per fresh request, its events or its error``."""
Snapshot = Callable[[int], str | None]
"""``snapshot(new_version) -> state JSON or None``, called after ``build``."""


@dataclass(frozen=True, slots=True)
class FleetGroup:
    """One fleet's requests in a group commit (:meth:`EventLog.append_groups`).

    Attributes
    ----------
    fleet_id
        The fleet.
    expected_version
        The version of the caller's cached state; the stored events after it
        are passed to ``build``.
    requests
        One ``(idempotency_key, request_hash)`` per request, in order (either
        may be ``None``).
    build
        ``build(missed, fresh) -> [events or error, ...]``, called under the
        fleet's lock with the missed events and the indices (into ``requests``)
        of the fresh requests; one entry per fresh request: a list of
        :class:`NewEvent` (possibly empty: nothing is written and the key is
        not recorded) or a :class:`~routing_svc.errors.RoutingSvcError` (that
        request fails alone). Not called when no request is fresh. If it
        raises, nothing at all is written and the exception propagates.
    snapshot
        ``snapshot(new_version) -> state JSON or None``, called once after
        ``build`` when events were built; a string is stored, in the same
        transaction, as the fleet's snapshot at ``new_version``.
    """

    fleet_id: str
    expected_version: int
    requests: tuple[tuple[str | None, str | None], ...]
    build: BuildGroup
    snapshot: Snapshot | None = None


@dataclass(frozen=True, slots=True)
class StagedGroup:
    """One fleet's share of a transaction, computed but not yet written."""

    rows: list[dict[str, Any]]
    """The ``events`` rows to insert."""
    move: tuple[str, int, str | None] | None
    """``(fleet, new version, snapshot or None)``, ``None`` when nothing is written."""
    items: list[GroupItem]
    """One item per request, in order."""


def check_groups(groups: Sequence[FleetGroup]) -> str:
    """Check the groups of one append; what the append is called in errors.

    Raises
    ------
    InvalidInput
        A bad version, key or hash, or two groups of one fleet.
    """
    for group in groups:
        q.check_version(group.expected_version)
        for key, digest in group.requests:
            q.check_key(key, "idempotency key")
            q.check_key(digest, "request hash")
    if len({group.fleet_id for group in groups}) != len(groups):
        raise InvalidInput("append_groups takes at most one group per fleet")
    return "append to fleets " + ", ".join(repr(g.fleet_id) for g in groups)


def write_groups(conn: Connection, groups: Sequence[FleetGroup]) -> list[list[GroupItem]]:
    """Stage and write ``groups`` in the open write transaction ``conn``; their items.

    The fleets' rows are locked in one statement, every event of the
    transaction is stamped with one moment, and nothing is committed.
    """
    versions = q.lock_fleets(conn, [group.fleet_id for group in groups])
    created_at = q.now()
    staged = [stage_group(conn, group, versions[group.fleet_id], created_at) for group in groups]
    q.insert_event_rows(conn, [row for stage in staged for row in stage.rows])
    q.move_versions(conn, [stage.move for stage in staged if stage.move is not None])
    return [stage.items for stage in staged]


def stage_group(
    conn: Connection, group: FleetGroup, version: int, created_at: datetime
) -> StagedGroup:
    """Build one fleet's group inside the open transaction ``conn``, whose row is
    locked at ``version``, with events stamped ``created_at``; the caller writes the
    rows and the version.

    Raises
    ------
    Conflict
        The group's ``expected_version`` is ahead of ``version``.
    InvalidInput
        ``build`` or ``snapshot`` returned something else than documented.
    """
    fleet_id, expected_version = group.fleet_id, group.expected_version
    requests, build, snapshot = group.requests, group.build, group.snapshot
    if expected_version > version:
        raise Conflict(
            f"fleet {fleet_id!r} is at version {version}; "
            f"the caller's cache claims version {expected_version}"
        )
    stored: dict[str, list[EventRecord]] = {}
    first_index: dict[str, int] = {}
    fresh: list[int] = []
    repeats: dict[int, int] = {}  # index of a repeated key -> its first occurrence
    for index, (key, _) in enumerate(requests):
        if key is None:
            fresh.append(index)
        elif key in first_index:
            repeats[index] = first_index[key]
        else:
            first_index[key] = index
            prior = q.keyed_batch(conn, fleet_id, key)
            if prior:
                stored[key] = prior
            else:
                fresh.append(index)
    # the events after the caller's version, if other writers appended any
    missed = (
        tuple(q.select_events(conn, fleet_id, after=expected_version))
        if version > expected_version
        else ()
    )
    built: list[list[NewEvent] | RoutingSvcError] = []
    if fresh:
        built = _checked_build(build(list(missed), list(fresh)), len(fresh))
    rows: list[dict[str, Any]] = []
    outcome: dict[int, tuple[tuple[EventRecord, ...], RoutingSvcError | None]] = {}
    for index, entry in zip(fresh, built, strict=True):
        if isinstance(entry, RoutingSvcError):
            outcome[index] = ((), entry)
            continue
        key, digest = requests[index]
        mine = q.event_rows(
            fleet_id,
            version + len(rows),
            entry,
            idempotency_key=key,
            request_hash=digest,
            created_at=created_at,
        )
        rows += mine
        outcome[index] = (q.records_of_rows(mine), None)
    new_version = version + len(rows)
    move: tuple[str, int, str | None] | None = None
    if rows:
        state = snapshot(new_version) if snapshot is not None else None
        if state is not None and not isinstance(state, str):
            raise InvalidInput("snapshot must return JSON text (str) or None")
        move = (fleet_id, new_version, state)
    items: list[GroupItem] = []
    for index, (key, digest) in enumerate(requests):
        first = repeats.get(index, index)
        duplicate = first != index
        if key is not None and key in stored:
            prior_events = stored[key]
            if prior_events[0].request_hash != digest:
                error: RoutingSvcError = Conflict(
                    f"idempotency key {key!r} was used for another request"
                )
                items.append(GroupItem(new_version, (), missed, False, error))
            else:
                items.append(GroupItem(new_version, tuple(prior_events), missed, True))
            continue
        events_of, failed = outcome[first]
        if duplicate and requests[first][1] != digest:
            failed = Conflict(f"idempotency key {key!r} was used for another request")
        if failed is not None:
            items.append(GroupItem(new_version, (), missed, False, failed))
        else:
            items.append(GroupItem(new_version, events_of, missed, duplicate))
    return StagedGroup(rows, move, items)


def _checked_build(
    built: Sequence[Sequence[NewEvent] | RoutingSvcError], expected: int
) -> list[list[NewEvent] | RoutingSvcError]:
    """Check ``build``'s answer: one entry of events or an error per fresh request."""
    if isinstance(built, str | bytes) or not isinstance(built, Sequence):
        raise InvalidInput("a group build must return a list with one entry per fresh request")
    entries = list(built)
    if len(entries) != expected:
        raise InvalidInput(
            f"a group build returned {len(entries)} entries for {expected} fresh requests"
        )
    return [
        entry if isinstance(entry, RoutingSvcError) else q.check_new_events(entry)
        for entry in entries
    ]
