"""Health (can the store take a write now?) and Prometheus metrics."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request, Response
from fastapi.responses import JSONResponse
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

from routing_svc.service.deps import fleet_service
from routing_svc.service.fleets import FleetService
from routing_svc.service.problems import retry_after_of
from routing_svc.service.responses import RETRY_AFTER, Health, problems
from routing_svc.service.store_health import StoreHealth

router = APIRouter(tags=["health"])

HEALTH_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"description": "The store can take writes now."},
    503: {
        "description": "Writes would fail now (`reason` says why); `Retry-After` is set.",
        "model": Health,
        "headers": RETRY_AFTER,
        # ... or a problem, when the request's deadline passed first
        "content": problems(503)[503]["content"],
    },
}
HEALTH_RESPONSES |= problems(500)


@router.get(
    "/healthz", response_model=Health, responses=HEALTH_RESPONSES, response_class=JSONResponse
)
async def healthz(
    request: Request, service: Annotated[FleetService, Depends(fleet_service)]
) -> JSONResponse:
    """200 when the store can take a write now, else 503 with the reason; answered within
    the health deadline (``health_timeout_s``) even when the database does not answer."""
    health: StoreHealth = request.app.state.store_health
    verdict = await health.check()
    body: dict[str, Any] = {
        "status": "ok" if verdict.reason is None else "unavailable",
        "database": service.log.dialect,
        "networks": len(service.networks.all()),
        "connections_in_use": verdict.connections_in_use,
    }
    if verdict.reason is None:
        return JSONResponse(body)
    body["reason"] = verdict.reason
    headers = {"Retry-After": str(retry_after_of(request.app))}
    return JSONResponse(body, status_code=503, headers=headers)


@router.get("/metrics", include_in_schema=False)
async def prometheus_metrics() -> Response:
    """Prometheus exposition of the process's metrics."""
    return Response(generate_latest(), media_type=CONTENT_TYPE_LATEST)
