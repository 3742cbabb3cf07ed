"""The FastAPI application: ``create_app(settings)``; nothing heavy at import time."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware

from routing_svc import __version__
from routing_svc.errors import Conflict, StorageError
from routing_svc.long_lived import frozen_heap
from routing_svc.network.identity import file_bytes_sha256
from routing_svc.service import fleet_gauges
from routing_svc.service.deadline import RequestDeadline
from routing_svc.service.demo import ensure_demo_fleet, feed_demo_targets
from routing_svc.service.fastpath import TargetFastPath
from routing_svc.service.fleets import FleetService
from routing_svc.service.guards import Guards
from routing_svc.service.networks import NetworkEntry, NetworkRegistry
from routing_svc.service.problems import install_problem_handlers
from routing_svc.service.responses import complete_document
from routing_svc.service.routes import (
    dashboard,
    fleets,
    health,
    networks,
    stream,
    targets,
    vehicles,
)
from routing_svc.service.settings import Settings
from routing_svc.service.store_health import StoreHealth
from routing_svc.store import EventLog, NetworkRecord


def load_networks(registry: NetworkRegistry, log: EventLog, settings: Settings) -> None:
    """Load the start-up networks and every network registered in the database.

    A network is registered under its identity
    (:func:`~routing_svc.network.identity.network_sha256`); a record stored under
    the former start-up identity of the same file is re-keyed first
    (:func:`rekey_legacy`).
    """
    for name, path in settings.networks.items():
        entry = registry.load(name, Path(path), name=name)
        known = {n.id: n for n in log.list_networks()}
        if name not in known:
            try:
                log.create_network(
                    name,
                    sha256=entry.network.source_sha256,
                    path=str(Path(path).resolve()),
                    name=name,
                )
                continue
            except Conflict:
                # another instance (or worker) starting at the same time registered it first
                known = {n.id: n for n in log.list_networks()}
        record = rekey_legacy(log, known[name], entry)
        if record.sha256 != entry.network.source_sha256:
            raise StorageError(
                f"network {name!r} is stored with other content (sha256 {record.sha256}) "
                f"than {path}; fleets on it would not replay. Use another name."
            )
    for record in log.list_networks():
        if record.id not in registry and Path(record.path).is_file():
            rekey_legacy(log, record, registry.load(record.id, Path(record.path), name=record.name))


def rekey_legacy(log: EventLog, record: NetworkRecord, entry: NetworkEntry) -> NetworkRecord:
    """``record``, moved to the identity of ``entry`` if it holds the former one.

    Start-up networks used to be stored under the SHA-256 of the file's bytes
    (for a ``.gz`` file, of the compressed bytes). When ``record`` holds that
    hash of ``entry``'s file, the record is re-keyed to the network's identity;
    any other hash is returned unchanged.
    """
    identity = entry.network.source_sha256
    if record.sha256 == identity or record.sha256 != file_bytes_sha256(entry.path):
        return record
    return log.rekey_network(record.id, old_sha256=record.sha256, new_sha256=identity)


def install_contract(app: FastAPI) -> None:
    """Serve the OpenAPI document with its problem answers made whole
    (:func:`~routing_svc.service.responses.complete_document`), built once."""
    build = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = complete_document(build())
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the application; the lifespan opens the store and loads networks."""
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        log = EventLog(
            settings.database_url,
            busy_timeout_ms=settings.db_busy_timeout_ms,
            timeouts=settings.store_timeouts(),
        ).open()
        registry = NetworkRegistry(data_dir=settings.data_dir, max_bytes=settings.max_network_bytes)
        feeder: asyncio.Task[None] | None = None
        service: FleetService | None = None
        try:
            load_networks(registry, log, settings)
            for entry in registry.all():
                await asyncio.to_thread(entry.warm_up)
            service = FleetService(
                log,
                registry,
                recent_window=settings.recent_window,
                consolidation_workers=settings.consolidation_workers,
            )
            fleet_gauges.COLLECTOR.track(service)
            app.state.settings = settings
            app.state.networks = registry
            app.state.fleets = service
            app.state.store_health = StoreHealth(
                log,
                timeout_s=settings.health_timeout_s,
                min_free_bytes=settings.health_min_free_bytes,
            )
            if settings.demo_fleet and registry.all():
                ensure_demo_fleet(service, registry.all()[0])
                if settings.demo_rate > 0:
                    feeder = asyncio.create_task(feed_demo_targets(service, settings.demo_rate))
            # What start-up built (modules, networks, the app) lives as long as the
            # process: kept out of the cyclic garbage collector's full passes, which
            # otherwise scan it all and stall the event loop under load.
            with frozen_heap():
                yield
        finally:
            if feeder is not None:
                feeder.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await feeder
            if service is not None:
                await service.drain()  # commits what the event loop queued
                await asyncio.to_thread(service.close)  # ... and the writer thread
            log.close()

    app = FastAPI(
        title="routing_svc",
        version=__version__,
        summary="Keeps a vehicle fleet where it is needed (stochastic approximation).",
        lifespan=lifespan,
        # one schema per model: answers are documented as they are validated (the
        # serialised form keeps the members in the order they were built)
        separate_input_output_schemas=False,
    )
    install_problem_handlers(app)
    install_contract(app)
    for router in (  # the hot routes first: the router tries routes in this order
        targets.router,
        health.router,
        networks.router,
        fleets.router,
        vehicles.router,
        stream.router,
        dashboard.router,
    ):
        app.include_router(router)
    if settings.target_fast_path:  # the innermost of the middleware added here
        app.add_middleware(TargetFastPath)
    app.add_middleware(
        RequestDeadline,
        timeout_s=settings.request_timeout_s,
        retry_after_s=settings.retry_after_s,
    )
    app.add_middleware(
        Guards,
        max_body_bytes=settings.max_body_bytes,
        max_upload_bytes=settings.max_network_bytes,
        api_key=settings.api_key,
    )
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "PUT", "DELETE"],
            allow_headers=["Content-Type", "Idempotency-Key", "X-API-Key"],
        )
    return app
