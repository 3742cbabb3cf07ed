"""``/v1/fleets``: create, read and delete fleets; their event log and metrics."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query, Response
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from routing_svc.service.creation import build_created_payload
from routing_svc.service.deadline import deadline_paused
from routing_svc.service.deps import fleet_service
from routing_svc.service.fleets import FleetService
from routing_svc.service.responses import (
    CONFLICT,
    FOUND,
    INVALID,
    READ,
    WRITE,
    EventPage,
    FleetAnswer,
    FleetList,
    FleetMetrics,
    problems,
)
from routing_svc.service.schemas import FleetSpec

router = APIRouter(
    prefix="/v1/fleets",
    tags=["fleets"],
    default_response_class=JSONResponse,  # json.dumps, as the answers always were written
    responses=READ,
)
Service = Annotated[FleetService, Depends(fleet_service)]


@router.post(
    "",
    status_code=201,
    response_model=FleetAnswer,
    responses=WRITE | FOUND | CONFLICT,
    response_model_exclude_unset=True,
)
async def create_fleet(spec: FleetSpec, service: Service) -> dict[str, Any]:
    """Create a fleet on a network (explicit positions or the optimum of a prior sample).

    The request's deadline bounds its waits on the store, not the solving of the start
    and the reference optimum."""
    entry = await run_in_threadpool(service.network, spec.network)
    async with deadline_paused():
        created = await run_in_threadpool(build_created_payload, spec, entry)
    return await run_in_threadpool(service.commit_fleet, spec, entry, created)


@router.get("", response_model=FleetList, response_model_exclude_unset=True)
async def list_fleets(service: Service) -> dict[str, Any]:
    """Every fleet with its vehicles."""
    return {"items": await run_in_threadpool(service.list_fleets)}


@router.get(
    "/{fleet_id}", response_model=FleetAnswer, responses=FOUND, response_model_exclude_unset=True
)
async def get_fleet(fleet_id: str, service: Service) -> dict[str, Any]:
    """A fleet: version, vehicles, types and reference positions."""
    return await run_in_threadpool(service.get_fleet, fleet_id)


@router.delete(
    "/{fleet_id}",
    status_code=204,
    response_class=Response,
    responses=FOUND | problems(400, 401),
)
async def delete_fleet(fleet_id: str, service: Service) -> Response:
    """Delete a fleet (its event log stays as an audit trail; the id is not reused)."""
    await run_in_threadpool(service.delete_fleet, fleet_id)
    return Response(status_code=204)


@router.get(
    "/{fleet_id}/events",
    response_model=EventPage,
    responses=FOUND | INVALID,
    response_model_exclude_unset=True,
)
async def list_events(
    fleet_id: str,
    service: Service,
    after: Annotated[int, Query(ge=0, le=2**62)] = 0,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
) -> dict[str, Any]:
    """The fleet's event log, ``limit`` events after ``after``."""
    items = await run_in_threadpool(service.events, fleet_id, after=after, limit=limit)
    return {"items": items, "next_after": items[-1]["seq"] if items else after}


@router.get(
    "/{fleet_id}/metrics",
    response_model=FleetMetrics,
    responses=FOUND,
    response_model_exclude_unset=True,
)
async def fleet_metrics(fleet_id: str, service: Service) -> dict[str, Any]:
    """Targets applied, mean costs, step sizes, update counts and the gap to the optimum."""
    return await run_in_threadpool(service.metrics, fleet_id)
