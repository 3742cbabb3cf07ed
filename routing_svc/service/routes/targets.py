"""Targets: serve them (with idempotency), ask who would, and feed travel times."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Header, Response
from prometheus_client import Counter
from starlette.concurrency import run_in_threadpool

from routing_svc.service.deps import fleet_service
from routing_svc.service.fleets import FleetService
from routing_svc.service.schemas import TargetBatch, TargetSpec, TravelTimes

router = APIRouter(prefix="/v1/fleets/{fleet_id}", tags=["targets"])
Service = Annotated[FleetService, Depends(fleet_service)]
IdempotencyKey = Annotated[str | None, Header(min_length=1, max_length=200)]

TARGETS_APPLIED = Counter("routing_svc_targets_total", "Targets applied (acknowledged)")

TARGET_RESPONSE: dict[int | str, dict[str, Any]] = {
    200: {
        "description": "The target was served and the last-arriving vehicle moved.",
        "content": {"application/json": {"schema": {"type": "object"}}},
    }
}


@router.post("/targets", responses=TARGET_RESPONSE, response_class=Response)
async def post_target(
    fleet_id: str,
    target: TargetSpec,
    service: Service,
    idempotency_key: IdempotencyKey = None,
) -> Response:
    """Serve a target: the closest vehicles per required type serve it and the one that
    arrives last moves a step toward it. A retry with the same ``Idempotency-Key``
    returns the stored answer and applies nothing."""
    results, _ = await run_in_threadpool(
        lambda: service.post_targets(
            fleet_id,
            [target],
            idempotency_key=idempotency_key,
            body=target.model_dump(mode="json"),
        )
    )
    TARGETS_APPLIED.inc()
    return Response(results[0], media_type="application/json")


@router.post("/targets:batch", responses=TARGET_RESPONSE, response_class=Response)
async def post_target_batch(
    fleet_id: str,
    batch: TargetBatch,
    service: Service,
    idempotency_key: IdempotencyKey = None,
) -> Response:
    """Serve a list of targets in order, in one transaction."""
    results, version = await run_in_threadpool(
        lambda: service.post_targets(
            fleet_id,
            batch.targets,
            idempotency_key=idempotency_key,
            body=batch.model_dump(mode="json"),
        )
    )
    TARGETS_APPLIED.inc(len(results))
    body = '{"version":' + str(version) + ',"results":[' + ",".join(results) + "]}"
    return Response(body, media_type="application/json")


@router.post("/assign")
async def assign(fleet_id: str, target: TargetSpec, service: Service) -> dict[str, Any]:
    """Who would serve this target; changes nothing."""
    return await run_in_threadpool(service.assign, fleet_id, target)


@router.put("/traveltimes")
async def put_travel_times(fleet_id: str, body: TravelTimes, service: Service) -> dict[str, Any]:
    """Replace per-edge travel times (seconds) of a ``cost = time`` fleet; recorded as an
    event so that replay stays exact."""
    return await run_in_threadpool(service.put_travel_times, fleet_id, dict(body.times))
