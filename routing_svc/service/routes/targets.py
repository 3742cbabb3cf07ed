"""Targets: serve them (with idempotency), ask who would, and feed travel times."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool

from routing_svc.service.deadline import request_deadline
from routing_svc.service.deps import IdempotencyKey, fleet_service
from routing_svc.service.fleets import FleetService
from routing_svc.service.responses import (
    CONFLICT,
    FOUND,
    READ,
    WRITE,
    Assignment,
    Posts,
    TargetBatchResult,
    TargetResult,
    TravelTimesResult,
)
from routing_svc.service.schemas import TargetBatch, TargetSpec, TravelTimes
from routing_svc.service.target_route import (
    FLEET_PREFIX,
    TARGET_ROUTE,
    TARGETS_APPLIED,
    submit_target,
)
from routing_svc.service.write_path import PendingAnswer

router = APIRouter(
    prefix=FLEET_PREFIX,
    tags=["targets"],
    default_response_class=JSONResponse,  # json.dumps, as the answers always were written
    responses=READ,
)
Service = Annotated[FleetService, Depends(fleet_service)]

TARGET_SPEC_REF = "#/components/schemas/TargetSpec"
"""The body schema of the single-target route (registered by ``/assign``'s body)."""

TARGET_RESPONSE: dict[int | str, dict[str, Any]] = (
    {
        200: {
            "description": "The target was served and the last-arriving vehicle moved.",
            "model": TargetResult,
        }
    }
    | WRITE
    | FOUND
    | CONFLICT
)
"""The answers of the single-target route (the fast path's too, see ``fastpath.py``)."""

BATCH_RESPONSE: dict[int | str, dict[str, Any]] = (
    {
        200: {
            "description": "The targets were served in order, in one transaction.",
            "model": TargetBatchResult,
        }
    }
    | WRITE
    | FOUND
    | CONFLICT
)


Submit = Callable[[asyncio.AbstractEventLoop | None], PendingAnswer]
"""``submit(loop)`` queues a request (``loop``: see :meth:`GroupCommit.submit`)."""


async def _committed(service: FleetService, fleet_id: str, submit: Submit) -> tuple[list[str], int]:
    """Queue a request (``submit``) and wait for its commit, until the request's deadline
    (:meth:`FleetService.settled`).

    The event loop only resolves the positions and queues the request (for
    itself to write) when the fleet is in memory; a fleet that must first be
    read from the database is queued from a worker thread, for the writer
    thread.
    """
    if service.is_cached(fleet_id):
        future = submit(asyncio.get_running_loop())
    else:
        future = await run_in_threadpool(submit, None)
    return await service.settled(future, deadline=request_deadline())


@router.post(
    TARGET_ROUTE,
    responses=TARGET_RESPONSE,
    response_class=Response,
    openapi_extra={
        "requestBody": {
            "required": True,
            "content": {"application/json": {"schema": {"$ref": TARGET_SPEC_REF}}},
        }
    },
)
async def post_target(
    fleet_id: str,
    request: Request,
    idempotency_key: IdempotencyKey = None,
) -> Response:
    """Serve a target: the closest vehicles per required type serve it and the one that
    arrives last moves a step toward it. A retry with the same ``Idempotency-Key``
    returns the stored answer and applies nothing.

    The body is a ``TargetSpec``; this hot route validates it straight from the
    bytes (pydantic's JSON parser) rather than through FastAPI's body handling,
    with the same problem+json answer for invalid input.
    """
    try:
        target = TargetSpec.model_validate_json(await request.body())
    except ValidationError as exc:
        raise RequestValidationError(exc.errors(include_url=False)) from None
    service: FleetService = request.app.state.fleets
    results, _ = await _committed(
        service,
        fleet_id,
        lambda loop: submit_target(service, fleet_id, target, idempotency_key, loop),
    )
    TARGETS_APPLIED.inc()
    return Response(results[0], media_type="application/json")


@router.post("/targets:batch", responses=BATCH_RESPONSE, response_class=Response)
async def post_target_batch(
    fleet_id: str,
    batch: TargetBatch,
    service: Service,
    idempotency_key: IdempotencyKey = None,
) -> Response:
    """Serve a list of targets in order, in one transaction."""
    body = batch.model_dump(mode="json") if idempotency_key is not None else None

    def submit(loop: asyncio.AbstractEventLoop | None) -> PendingAnswer:
        return service.submit_targets(
            fleet_id, batch.targets, idempotency_key=idempotency_key, body=body, loop=loop
        )

    results, version = await _committed(service, fleet_id, submit)
    TARGETS_APPLIED.inc(len(results))
    answer = '{"version":' + str(version) + ',"results":[' + ",".join(results) + "]}"
    return Response(answer, media_type="application/json")


@router.post("/assign", response_model=Assignment, responses=WRITE | FOUND)
async def assign(fleet_id: str, target: TargetSpec, service: Service) -> dict[str, Any]:
    """Who would serve this target; changes nothing."""
    return await run_in_threadpool(service.assign, fleet_id, target)


@router.get("/posts", response_model=Posts, responses=FOUND)
async def posts(fleet_id: str, service: Service) -> dict[str, Any]:
    """Where each available vehicle should wait now: per type, the references of all its
    vehicles that serve the recent targets best with as many vehicles as are available,
    held by the available ones at the least total travel time; changes nothing."""
    return await run_in_threadpool(service.posts, fleet_id)


@router.put("/traveltimes", response_model=TravelTimesResult, responses=WRITE | FOUND | CONFLICT)
async def put_travel_times(fleet_id: str, body: TravelTimes, service: Service) -> dict[str, Any]:
    """Replace per-edge travel times (seconds) of a ``cost = time`` fleet; recorded as an
    event so that replay stays exact."""
    return await run_in_threadpool(service.put_travel_times, fleet_id, dict(body.times))
