"""Plain records that the event-log store hands in and out.

The store never interprets the JSON it keeps: every ``*_json`` field is text
produced by the caller and returned byte for byte, so exact float round trips
stay the caller's business.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any, NamedTuple

from routing_svc.errors import RoutingSvcError

__all__ = [
    "EventRecord",
    "FleetRecord",
    "GroupItem",
    "NetworkRecord",
    "NewEvent",
    "as_utc",
]


def as_utc(moment: datetime) -> datetime:
    """Return ``moment`` as an aware UTC datetime.

    SQLite keeps no time zone, so a stored UTC timestamp reads back naive.
    """
    if moment.tzinfo is UTC:
        return moment
    if moment.tzinfo is None:
        return moment.replace(tzinfo=UTC)
    return moment.astimezone(UTC)


class NewEvent(NamedTuple):
    """An event that an append is about to write.

    Parameters
    ----------
    kind
        Event kind, e.g. ``"target"`` or ``"weights_updated"``.
    payload_json
        The event's input, JSON text.
    result_json
        What applying the event produced (the outcome a retry must return),
        JSON text, or ``None``.
    """

    kind: str
    payload_json: str
    result_json: str | None = None


class EventRecord(NamedTuple):
    """A stored event: number ``seq`` of fleet ``fleet_id`` (numbers start at 1)."""

    fleet_id: str
    seq: int
    kind: str
    payload_json: str
    result_json: str | None
    idempotency_key: str | None
    request_hash: str | None
    created_at: datetime

    @classmethod
    def from_row(cls, row: Any) -> EventRecord:
        """Build a record from a row of the ``events`` table."""
        return cls(
            fleet_id=row.fleet_id,
            seq=row.seq,
            kind=row.kind,
            payload_json=row.payload,
            result_json=row.result,
            idempotency_key=row.idempotency_key,
            request_hash=row.request_hash,
            created_at=as_utc(row.created_at),
        )


@dataclass(frozen=True, slots=True)
class GroupItem:
    """What :meth:`EventLog.append_groups` did for one request of a group.

    Attributes
    ----------
    version
        The fleet's version after the whole group committed (the same for
        every item of a group).
    events
        The events this request wrote; for a duplicate, the events that the
        first request with the same idempotency key wrote; empty on error.
    missed
        The stored events after the caller's ``expected_version`` that existed
        before the group's own events (the same for every item of a group).
    duplicate
        ``True`` when the idempotency key had been used (earlier, or by an
        earlier request of the same group): nothing was written for it.
    error
        The error of a request that failed alone (an idempotency key used for
        another request, or the domain error its ``build`` entry reported);
        ``None`` on success.
    """

    version: int
    events: tuple[EventRecord, ...]
    missed: tuple[EventRecord, ...]
    duplicate: bool
    error: RoutingSvcError | None = None


@dataclass(frozen=True, slots=True)
class NetworkRecord:
    """A registered road network file."""

    id: str
    sha256: str
    path: str
    name: str
    created_at: datetime
    meta_json: str

    @classmethod
    def from_row(cls, row: Any) -> NetworkRecord:
        """Build a record from a row of the ``networks`` table."""
        return cls(
            id=row.id,
            sha256=row.sha256,
            path=row.path,
            name=row.name,
            created_at=as_utc(row.created_at),
            meta_json=row.meta,
        )


@dataclass(frozen=True, slots=True)
class FleetRecord:
    """A fleet row: its configuration, version and latest snapshot.

    ``state_json`` is the snapshot taken at ``snapshot_version`` (both ``None``
    when no snapshot has been saved); events after ``snapshot_version`` must be
    replayed on top of it.
    """

    id: str
    network_id: str
    config_json: str
    version: int
    state_json: str | None
    snapshot_version: int | None
    created_at: datetime
    deleted: bool

    @classmethod
    def from_row(cls, row: Any) -> FleetRecord:
        """Build a record from a row of the ``fleets`` table."""
        return cls(
            id=row.id,
            network_id=row.network_id,
            config_json=row.config,
            version=row.version,
            state_json=row.state,
            snapshot_version=row.snapshot_version,
            created_at=as_utc(row.created_at),
            deleted=bool(row.deleted),
        )
