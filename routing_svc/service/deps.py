"""Request-scoped access to the application's services, and the headers write routes share."""

from __future__ import annotations

from typing import Annotated

from fastapi import Header, Request

from routing_svc.service.fleets import FleetService
from routing_svc.service.networks import NetworkRegistry
from routing_svc.service.settings import Settings


def fleet_service(request: Request) -> FleetService:
    service: FleetService = request.app.state.fleets
    return service


def network_registry(request: Request) -> NetworkRegistry:
    registry: NetworkRegistry = request.app.state.networks
    return registry


def settings(request: Request) -> Settings:
    value: Settings = request.app.state.settings
    return value


MAX_IDEMPOTENCY_KEY = 200
"""The longest ``Idempotency-Key`` a write route accepts."""

IdempotencyKey = Annotated[str | None, Header(min_length=1, max_length=MAX_IDEMPOTENCY_KEY)]
"""The ``Idempotency-Key`` header of a write route."""


def usable_idempotency_key(key: str) -> bool:
    """Whether a write route accepts ``key`` (:data:`IdempotencyKey`'s bounds)."""
    return 1 <= len(key) <= MAX_IDEMPOTENCY_KEY
