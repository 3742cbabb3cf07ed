"""Request-scoped access to the application's services."""

from __future__ import annotations

from fastapi import Request

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
