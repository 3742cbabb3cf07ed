"""Vehicles' live state: status and current position, one vehicle or many at once.

Each request is one ``vehicle_state`` event, written through the fleet
service's group commit like a target, so it is durable when answered, a retry
with the same ``Idempotency-Key`` applies nothing twice, and replay restores
the state exactly.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends
from starlette.concurrency import run_in_threadpool

from routing_svc.service.deps import IdempotencyKey, fleet_service
from routing_svc.service.fleets import FleetService
from routing_svc.service.responses import CONFLICT, FOUND, WRITE, VehicleStateResult
from routing_svc.service.schemas import (
    Identifier,
    VehicleStateBatch,
    VehicleStateChange,
    VehicleStateSpec,
)

router = APIRouter(prefix="/v1/fleets/{fleet_id}/vehicles", tags=["vehicles"])
Service = Annotated[FleetService, Depends(fleet_service)]


STATE_ERRORS = WRITE | FOUND | CONFLICT
"""Unknown fleet, vehicle or edge (404); a timestamp before the vehicle's last one, a deleted
fleet or an ``Idempotency-Key`` reused with another body (409); a status not one of the
three or a position off the network (422)."""


async def _apply(
    service: FleetService,
    fleet_id: str,
    changes: list[VehicleStateChange],
    body: Any,
    idempotency_key: str | None,
) -> dict[str, Any]:
    return await run_in_threadpool(
        lambda: service.put_vehicle_states(
            fleet_id,
            changes,
            idempotency_key=idempotency_key,
            body=body if idempotency_key is not None else None,
        )
    )


@router.put("/{vehicle_id}/state", response_model=VehicleStateResult, responses=STATE_ERRORS)
async def put_vehicle_state(
    fleet_id: str,
    vehicle_id: Identifier,
    state: VehicleStateSpec,
    service: Service,
    idempotency_key: IdempotencyKey = None,
) -> dict[str, Any]:
    """Set one vehicle's status (``available``, ``busy``, ``offline``) and, optionally, its
    current position and the time it was observed."""
    given = {name: getattr(state, name) for name in state.model_fields_set}
    change = VehicleStateChange.model_validate({**given, "vehicle": vehicle_id})
    body = {"vehicle": vehicle_id, **state.model_dump(mode="json", exclude_unset=True)}
    return await _apply(service, fleet_id, [change], body, idempotency_key)


@router.put("/state", response_model=VehicleStateResult, responses=STATE_ERRORS)
@router.post("/state:batch", response_model=VehicleStateResult, responses=STATE_ERRORS)
async def put_vehicle_states(
    fleet_id: str,
    batch: VehicleStateBatch,
    service: Service,
    idempotency_key: IdempotencyKey = None,
) -> dict[str, Any]:
    """Set many vehicles' states in order, all or none (one event); ``PUT .../state`` and
    ``POST .../state:batch`` are the same operation."""
    body = batch.model_dump(mode="json", exclude_unset=True)
    return await _apply(service, fleet_id, batch.changes, body, idempotency_key)
