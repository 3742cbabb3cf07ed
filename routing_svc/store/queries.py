"""The SQL statements and argument checks behind :class:`~routing_svc.store.EventLog`.

Every function takes an open :class:`~sqlalchemy.engine.Connection` inside the
caller's transaction and never commits.
"""

from __future__ import annotations

import functools
import operator
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from typing import Any

import sqlalchemy as sa
from sqlalchemy.engine import Connection, Dialect

from routing_svc.errors import InvalidInput, UnknownFleet
from routing_svc.store.records import EventRecord, NewEvent, as_utc
from routing_svc.store.schema import ID_LENGTH, KEY_LENGTH, KIND_LENGTH, events, fleets, networks

__all__ = [
    "check_id",
    "check_key",
    "check_new_events",
    "check_version",
    "event_rows",
    "fleet_event_stats",
    "insert_event_rows",
    "keyed_batch",
    "lock_fleet",
    "lock_fleets",
    "move_versions",
    "now",
    "records_of_rows",
    "select_events",
    "select_fleet",
    "select_network",
]


# The statements of the write path, built once (their compiled form is cached).
_FLEET_KEY: sa.BindParameter[str] = sa.bindparam("fleet_key")
_SELECT_FLEET = sa.select(fleets).where(fleets.c.id == _FLEET_KEY)
_LOCK_FLEET = _SELECT_FLEET.with_for_update()
_LOCK_FLEETS = (
    sa.select(fleets.c.id, fleets.c.version, fleets.c.deleted)
    .where(fleets.c.id.in_(sa.bindparam("fleet_keys", expanding=True)))
    .order_by(fleets.c.id)
    .with_for_update()
)
_UPDATE_FLEET = sa.update(fleets).where(fleets.c.id == _FLEET_KEY)
_INSERT_EVENTS = sa.insert(events)
_SELECT_EVENTS = (
    sa.select(events)
    .where(events.c.fleet_id == _FLEET_KEY, events.c.seq > sa.bindparam("after"))
    .order_by(events.c.seq)
)
_SELECT_EVENTS_PAGE = _SELECT_EVENTS.limit(sa.bindparam("limit"))
_SELECT_KEY = sa.select(events.c.seq, events.c.batch_size).where(
    events.c.fleet_id == _FLEET_KEY, events.c.idempotency_key == sa.bindparam("key")
)


def now() -> datetime:
    """The current time, aware, in UTC."""
    return datetime.now(UTC)


def check_id(value: str, what: str) -> None:
    """Raise :class:`InvalidInput` unless ``value`` is an id of 1 to 128 characters."""
    if not isinstance(value, str) or not 0 < len(value) <= ID_LENGTH:
        raise InvalidInput(f"{what} must be a string of 1 to {ID_LENGTH} characters")


def check_key(value: str | None, what: str) -> None:
    """Raise :class:`InvalidInput` unless ``value`` is ``None`` or 1 to 255 characters."""
    if value is not None and (not isinstance(value, str) or not 0 < len(value) <= KEY_LENGTH):
        raise InvalidInput(f"{what} must be a string of 1 to {KEY_LENGTH} characters")


def check_version(value: int) -> None:
    """Raise :class:`InvalidInput` unless ``value`` is an integer >= 0."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise InvalidInput(f"a version must be an integer >= 0, not {value!r}")


def check_new_events(new: Sequence[NewEvent]) -> list[NewEvent]:
    """Return ``new`` as a list after checking that it holds valid :class:`NewEvent` s."""
    checked = list(new)
    for item in checked:
        if not isinstance(item, NewEvent):
            raise InvalidInput(f"build must return NewEvent objects, not {type(item).__name__}")
        if not isinstance(item.kind, str) or not 0 < len(item.kind) <= KIND_LENGTH:
            raise InvalidInput(f"event kind must have 1 to {KIND_LENGTH} characters")
        if not isinstance(item.payload_json, str) or not isinstance(item.result_json, str | None):
            raise InvalidInput("event payload and result must be JSON text (str)")
    return checked


def event_rows(
    fleet_id: str,
    version: int,
    new: Sequence[NewEvent],
    *,
    idempotency_key: str | None,
    request_hash: str | None,
    created_at: datetime,
) -> list[dict[str, Any]]:
    """Rows of ``events`` for ``new``, numbered from ``version + 1``.

    The idempotency key and request hash go on the first row of the batch; every
    row records the batch size, so a retry can find the whole batch again.
    """
    return [
        {
            "fleet_id": fleet_id,
            "seq": version + 1 + index,
            "kind": item.kind,
            "payload": item.payload_json,
            "result": item.result_json,
            "idempotency_key": idempotency_key if index == 0 else None,
            "request_hash": request_hash if index == 0 else None,
            "batch_size": len(new),
            "created_at": created_at,
        }
        for index, item in enumerate(new)
    ]


def records_of_rows(rows: Sequence[dict[str, Any]]) -> tuple[EventRecord, ...]:
    """The :class:`EventRecord` s of rows built by :func:`event_rows`."""
    return tuple(
        EventRecord(
            fleet_id=row["fleet_id"],
            seq=row["seq"],
            kind=row["kind"],
            payload_json=row["payload"],
            result_json=row["result"],
            idempotency_key=row["idempotency_key"],
            request_hash=row["request_hash"],
            created_at=as_utc(row["created_at"]),
        )
        for row in rows
    )


# The write path's hot statements on SQLite go straight to the driver: the same SQL
# that SQLAlchemy renders for the statements above, without its per-call work.
_SQLITE_EVENT_COLUMNS = (
    "fleet_id", "seq", "kind", "payload", "result", "idempotency_key", "request_hash",
    "batch_size", "created_at",
)  # fmt: skip
_sqlite_event_values = operator.itemgetter(*_SQLITE_EVENT_COLUMNS[:-1])
"""A row's values in the order of :data:`_SQLITE_INSERT_EVENTS`, but its ``created_at``."""
_SQLITE_INSERT_EVENTS = (
    f"INSERT INTO events ({', '.join(_SQLITE_EVENT_COLUMNS)}) "
    f"VALUES ({', '.join('?' for _ in _SQLITE_EVENT_COLUMNS)})"
)
_SQLITE_MOVE_VERSION = "UPDATE fleets SET version = ? WHERE id = ?"
_SQLITE_MOVE_VERSION_AND_STATE = (
    "UPDATE fleets SET version = ?, state = ?, snapshot_version = ? WHERE id = ?"
)


def _sqlite_driver(conn: Connection) -> Any | None:
    """The driver's connection under ``conn`` on SQLite, else ``None``."""
    if conn.dialect.name != "sqlite":
        return None
    return conn.connection.dbapi_connection


@functools.lru_cache(maxsize=8)
def _created_at_processor(dialect: Dialect) -> Callable[[Any], Any]:
    """How ``dialect`` binds an ``events.created_at`` value (built once per dialect)."""
    stamp = events.c.created_at.type.dialect_impl(dialect).bind_processor(dialect)
    assert stamp is not None
    return stamp


def insert_event_rows(conn: Connection, rows: list[dict[str, Any]]) -> None:
    """Insert event rows (of any fleets) in one statement."""
    if not rows:
        return
    driver = _sqlite_driver(conn)
    if driver is None:
        conn.execute(_INSERT_EVENTS, rows)
        return
    stamp = _created_at_processor(conn.dialect)
    stamps = {moment: (stamp(moment),) for moment in {row["created_at"] for row in rows}}
    driver.executemany(
        _SQLITE_INSERT_EVENTS,
        [_sqlite_event_values(row) + stamps[row["created_at"]] for row in rows],
    )


def move_versions(conn: Connection, moves: Sequence[tuple[str, int, str | None]]) -> None:
    """Set each ``(fleet, version, state)``'s version, and its snapshot where ``state`` is
    JSON text; at most two statements, however many fleets."""
    plain = [
        {"fleet_key": fleet, "version": version} for fleet, version, state in moves if not state
    ]
    saved = [
        {"fleet_key": fleet, "version": version, "state": state, "snapshot_version": version}
        for fleet, version, state in moves
        if state
    ]
    driver = _sqlite_driver(conn)
    if driver is not None:
        if plain:
            driver.executemany(
                _SQLITE_MOVE_VERSION, [(p["version"], p["fleet_key"]) for p in plain]
            )
        if saved:
            driver.executemany(
                _SQLITE_MOVE_VERSION_AND_STATE,
                [(p["version"], p["state"], p["snapshot_version"], p["fleet_key"]) for p in saved],
            )
        return
    for params in (plain, saved):
        if params:
            conn.execute(_UPDATE_FLEET, params)


def lock_fleets(conn: Connection, fleet_ids: Sequence[str]) -> dict[str, int]:
    """Lock live fleets' rows for this transaction, in id order; their versions.

    One ``SELECT ... FOR UPDATE`` on PostgreSQL (rows locked in id order, as
    every writer does, so two writers cannot deadlock); on SQLite the write lock
    of ``BEGIN IMMEDIATE`` does the same job.

    Raises
    ------
    UnknownFleet
        One of the fleets does not exist or was deleted.
    """
    keys = sorted(set(fleet_ids))
    driver = _sqlite_driver(conn)
    if driver is None:
        rows = conn.execute(_LOCK_FLEETS, {"fleet_keys": keys}).all()
        versions = {row.id: int(row.version) for row in rows if not row.deleted}
    else:
        marks = ", ".join("?" for _ in keys)
        found = driver.execute(
            f"SELECT id, version, deleted FROM fleets WHERE id IN ({marks})", keys
        ).fetchall()
        versions = {key: int(version) for key, version, deleted in found if not deleted}
    for fleet_id in fleet_ids:
        if fleet_id not in versions:
            raise UnknownFleet(f"no fleet {fleet_id!r}")
    return versions


def select_network(conn: Connection, network_id: str) -> Any:
    """The ``networks`` row of ``network_id``, or ``None``."""
    return conn.execute(sa.select(networks).where(networks.c.id == network_id)).one_or_none()


def select_fleet(conn: Connection, fleet_id: str) -> Any:
    """The ``fleets`` row of ``fleet_id`` (deleted or not), or ``None``."""
    return conn.execute(_SELECT_FLEET, {"fleet_key": fleet_id}).one_or_none()


def lock_fleet(conn: Connection, fleet_id: str) -> Any:
    """Lock a live fleet's row for this transaction and return it.

    ``SELECT ... FOR UPDATE`` on PostgreSQL; on SQLite the clause is not
    rendered and the write lock of ``BEGIN IMMEDIATE`` does the same job.

    Raises
    ------
    UnknownFleet
        No such fleet, or it was deleted.
    """
    row = conn.execute(_LOCK_FLEET, {"fleet_key": fleet_id}).one_or_none()
    if row is None or row.deleted:
        raise UnknownFleet(f"no fleet {fleet_id!r}")
    return row


def select_events(
    conn: Connection, fleet_id: str, *, after: int, limit: int | None = None
) -> list[EventRecord]:
    """The events of ``fleet_id`` with ``seq > after`` in order, at most ``limit``."""
    if limit is None:
        rows = conn.execute(_SELECT_EVENTS, {"fleet_key": fleet_id, "after": after})
    else:
        params = {"fleet_key": fleet_id, "after": after, "limit": limit}
        rows = conn.execute(_SELECT_EVENTS_PAGE, params)
    return [EventRecord.from_row(row) for row in rows]


def keyed_batch(conn: Connection, fleet_id: str, key: str) -> list[EventRecord]:
    """The events written by the append that used idempotency ``key`` (or ``[]``)."""
    first = conn.execute(_SELECT_KEY, {"fleet_key": fleet_id, "key": key}).one_or_none()
    if first is None:
        return []
    query = (
        sa.select(events)
        .where(
            events.c.fleet_id == fleet_id,
            events.c.seq >= first.seq,
            events.c.seq < first.seq + first.batch_size,
        )
        .order_by(events.c.seq)
    )
    return [EventRecord.from_row(row) for row in conn.execute(query)]


def fleet_event_stats(conn: Connection) -> list[str]:
    """Problems with event numbering: each fleet must hold events ``1..version``."""
    query = (
        sa.select(
            fleets.c.id,
            fleets.c.version,
            sa.func.count(events.c.seq),
            sa.func.min(events.c.seq),
            sa.func.max(events.c.seq),
        )
        .select_from(fleets.outerjoin(events, events.c.fleet_id == fleets.c.id))
        .group_by(fleets.c.id, fleets.c.version)
        .order_by(fleets.c.id)
    )
    problems = []
    for fleet_id, version, count, low, high in conn.execute(query):
        # With a primary key on (fleet_id, seq), count == max == version and
        # min == 1 means exactly 1..version.
        if count != version or (count > 0 and (low != 1 or high != version)):
            problems.append(
                f"fleet {fleet_id!r}: version {version} but {count} events numbered {low}..{high}"
            )
    return problems
