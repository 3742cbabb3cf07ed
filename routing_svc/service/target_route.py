"""The single-target route's one definition: its path and how it queues a target.

Both ways in share it: the FastAPI route (:mod:`routing_svc.service.routes.targets`)
and the ASGI fast path (:mod:`routing_svc.service.fastpath`).
"""

from __future__ import annotations

import asyncio

from prometheus_client import Counter
from starlette.routing import compile_path

from routing_svc.service.fleets import FleetService
from routing_svc.service.schemas import TargetSpec
from routing_svc.service.write_path import PendingAnswer

__all__ = ["FLEET_PREFIX", "TARGETS_APPLIED", "TARGET_PATH", "TARGET_ROUTE", "submit_target"]

FLEET_PREFIX = "/v1/fleets/{fleet_id}"
"""The prefix of every route of one fleet."""

TARGET_ROUTE = "/targets"
"""The single-target route, under :data:`FLEET_PREFIX`."""

TARGET_PATH = compile_path(FLEET_PREFIX + TARGET_ROUTE)[0]
"""The route's full path as the router matches it (group ``fleet_id``)."""

TARGETS_APPLIED = Counter("routing_svc_targets_total", "Targets applied (acknowledged)")


def submit_target(
    service: FleetService,
    fleet_id: str,
    target: TargetSpec,
    idempotency_key: str | None,
    loop: asyncio.AbstractEventLoop | None = None,
) -> PendingAnswer:
    """Queue one target of the single-target route for the service's writer.

    Its ``Idempotency-Key`` digest covers the target as JSON. Raises (and
    queues nothing) when the target's position is invalid.
    """
    body = target.model_dump(mode="json") if idempotency_key is not None else None
    return service.submit_targets(
        fleet_id, [target], idempotency_key=idempotency_key, body=body, loop=loop
    )
