"""From the API's vehicle state changes to the fleet's :class:`VehicleState` values.

A change names a vehicle, its status, and optionally a position and a
timestamp. A change without ``position`` keeps the vehicle's current
position; ``"position": null`` puts it back at its reference. The timestamp
(seconds since the epoch, or an ISO 8601 time with a zone) may not go back
before the vehicle's last one (:meth:`routing_svc.sa.Fleet.set_states`).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime

from routing_svc.sa.live import Status, VehicleState
from routing_svc.service.runtime import FleetRuntime
from routing_svc.service.schemas import VehicleStateChange
from routing_svc.types import NetPosition


def epoch_seconds(timestamp: float | datetime | None) -> float | None:
    """A change's timestamp in seconds since the epoch."""
    if timestamp is None or isinstance(timestamp, float | int):
        return None if timestamp is None else float(timestamp)
    return timestamp.timestamp()


def resolve_changes(
    runtime: FleetRuntime, resolved: Sequence[tuple[VehicleStateChange, NetPosition | None]]
) -> list[tuple[str, VehicleState[NetPosition]]]:
    """The fleet's new states for ``resolved`` (each change with its snapped position).

    Raises
    ------
    NotFound
        An unknown vehicle (before anything changed).
    """
    current: dict[str, NetPosition | None] = {}
    out: list[tuple[str, VehicleState[NetPosition]]] = []
    for change, position in resolved:
        vid = change.vehicle
        if "position" in change.model_fields_set:
            where = position
        elif vid in current:
            where = current[vid]
        else:
            where = runtime.fleet.vehicle_state(vid).position
        current[vid] = where
        out.append(
            (vid, VehicleState(Status(change.status), where, epoch_seconds(change.timestamp)))
        )
    return out
