"""Liveness and Prometheus metrics."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from starlette.concurrency import run_in_threadpool

from routing_svc.service.deps import fleet_service
from routing_svc.service.fleets import FleetService

router = APIRouter(tags=["health"])


@router.get("/healthz")
async def healthz(service: Annotated[FleetService, Depends(fleet_service)]) -> dict[str, Any]:
    """The service is up and its database answers."""
    fleets = await run_in_threadpool(service.log.list_fleets)
    return {
        "status": "ok",
        "database": service.log.dialect,
        "networks": len(service.networks.all()),
        "fleets": len(fleets),
    }


@router.get("/metrics", include_in_schema=False)
async def prometheus_metrics() -> Response:
    """Prometheus exposition of the process's metrics."""
    return Response(generate_latest(), media_type=CONTENT_TYPE_LATEST)
