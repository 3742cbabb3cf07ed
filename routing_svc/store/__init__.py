"""Event-log store: fleets as streams of JSON events, on SQLite or PostgreSQL.

::

    from routing_svc.store import FleetGroup, NewEvent, open_event_log

    with open_event_log("sqlite:///var/routing.db") as log:
        log.create_network("grid", sha256=digest, path=str(path), name="grid")
        log.create_fleet("taxis", "grid", config_json, created_payload_json)
        ((item,),) = log.append_groups(
            [
                FleetGroup(
                    "taxis",
                    expected_version=cached_version,
                    requests=((key, digest_of_request),),
                    build=lambda missed, fresh: [[NewEvent("target", payload, result)]],
                )
            ]
        )

Modules: :mod:`~routing_svc.store.event_log` (the :class:`EventLog` API),
:mod:`~routing_svc.store.staging` (the rows of a group commit),
:mod:`~routing_svc.store.records` (records in and out),
:mod:`~routing_svc.store.schema` (tables), :mod:`~routing_svc.store.queries`
(statements), :mod:`~routing_svc.store.engine` (durability settings, checks,
migrations), ``migrations/`` (Alembic scripts, run at :meth:`EventLog.open`).
"""

from routing_svc.store.event_log import (
    FLEET_CREATED,
    FLEET_DELETED,
    EventLog,
    UncommittedAppend,
    open_event_log,
)
from routing_svc.store.records import (
    EventRecord,
    FleetRecord,
    GroupItem,
    NetworkRecord,
    NewEvent,
)
from routing_svc.store.staging import BuildGroup, FleetGroup, Snapshot

__all__ = [
    "FLEET_CREATED",
    "FLEET_DELETED",
    "BuildGroup",
    "EventLog",
    "EventRecord",
    "FleetGroup",
    "FleetRecord",
    "GroupItem",
    "NetworkRecord",
    "NewEvent",
    "Snapshot",
    "UncommittedAppend",
    "open_event_log",
]
