"""``/v1/networks``: upload, list and draw road networks."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from routing_svc.errors import Conflict, InvalidInput, NotFound, OffNetwork, PayloadTooLarge
from routing_svc.service.deps import fleet_service, network_registry
from routing_svc.service.fleets import FleetService
from routing_svc.service.networks import NetworkRegistry
from routing_svc.service.responses import (
    CONFLICT,
    FOUND,
    READ,
    WRITE,
    Geometry,
    NetworkAnswer,
    NetworkList,
    ResolvedPositions,
)
from routing_svc.service.schemas import Identifier, PositionBatch

router = APIRouter(
    prefix="/v1/networks",
    tags=["networks"],
    default_response_class=JSONResponse,  # json.dumps, as the answers always were written
    responses=READ,
)

NET_FILE = {"type": "string", "format": "binary"}
NET_BODY = {
    "requestBody": {
        "required": True,
        "description": "A SUMO road network (`.net.xml`) or an OpenStreetMap extract "
        "(root `<osm>`, converted as `routing-svc import-osm` does), plain or "
        "gzip-compressed, at most `max_network_bytes` (setting "
        "`ROUTING_SVC_MAX_NETWORK_BYTES`) as sent. The service checks what JSON Schema "
        "cannot: well-formed XML inside the service's XML limits, a SUMO `<net>` (or an "
        "extract netconvert builds one from) with usable edges for passenger cars. Anything "
        "else is a 422 (`invalid-network`, `xml-limit-exceeded`); a larger body is a 413.",
        "content": {
            "application/xml": {"schema": NET_FILE},
            "application/gzip": {"schema": NET_FILE},
        },
    }
}


async def read_limited(request: Request, limit: int) -> bytearray:
    """The request body, at most ``limit`` bytes, held once in memory.

    With a ``Content-Length`` the buffer is allocated once at that size;
    without one it grows as chunks arrive. Past ``limit``: ``PayloadTooLarge``.
    """
    declared = request.headers.get("content-length")
    expected = int(declared) if declared and declared.isdigit() else 0
    data = bytearray(min(expected, limit))
    size = 0
    async for chunk in request.stream():
        if size + len(chunk) > limit:
            raise PayloadTooLarge(f"the body exceeds the limit of {limit} bytes")
        if size + len(chunk) <= len(data):
            data[size : size + len(chunk)] = chunk
        else:
            del data[size:]
            data += chunk
        size += len(chunk)
    del data[size:]
    return data


UPLOAD_RESPONSES: dict[int | str, dict[str, Any]] = (
    {
        200: {
            "description": "The network is already known under this id with the same content.",
            "model": NetworkAnswer,
        },
    }
    | WRITE
    | CONFLICT
)


@router.post(
    "",
    status_code=201,
    response_model=NetworkAnswer,
    responses=UPLOAD_RESPONSES,
    openapi_extra=NET_BODY,
)
async def upload_network(
    request: Request,
    response: Response,
    registry: Annotated[NetworkRegistry, Depends(network_registry)],
    service: Annotated[FleetService, Depends(fleet_service)],
    name: Annotated[Identifier | None, Query()] = None,
) -> dict[str, Any]:
    """Upload a SUMO ``.net.xml`` or ``.net.xml.gz``, or an OpenStreetMap extract
    (``.osm``, ``.osm.xml``, plain or gzip); it is checked, compiled and kept.

    An upload whose root element is ``<osm>`` is converted with SUMO's
    netconvert and SUMO's recommended OpenStreetMap options (as
    ``routing-svc import-osm``), under the same size and XML limits; the answer
    is then the same as for the network it became.

    A network is identified by the SHA-256 of its plain XML, whether it was
    named at start-up or uploaded, gzipped or not. The same content under a
    known id answers 200 with that network; other content under a known id
    is a 409.
    """
    data = await read_limited(request, registry.max_bytes)

    def register() -> dict[str, Any]:
        digest, path, written = registry.store_upload(data)
        network_id = name or digest[:12]
        try:
            if network_id in registry:
                existing = registry.get(network_id)
                if existing.network.source_sha256 != digest:
                    raise Conflict(f"network {network_id!r} exists with other content")
                response.status_code = 200
                return existing.summary()
            entry = registry.load(network_id, path, name=name or network_id)
            service.log.create_network(network_id, sha256=digest, path=str(path), name=entry.name)
            return entry.summary()
        except BaseException:
            if written:  # a refused upload leaves nothing behind
                registry.discard_upload(path)
            raise

    return await run_in_threadpool(register)


@router.get("", response_model=NetworkList)
async def list_networks(
    registry: Annotated[NetworkRegistry, Depends(network_registry)],
) -> dict[str, Any]:
    """Every network the service knows."""
    return {"items": [e.summary() for e in registry.all()]}


@router.get("/{network_id}", response_model=NetworkAnswer, responses=FOUND)
async def get_network(
    network_id: str, service: Annotated[FleetService, Depends(fleet_service)]
) -> dict[str, Any]:
    """One network's counts and bounds."""
    entry = await run_in_threadpool(service.network, network_id)
    return entry.summary()


@router.get("/{network_id}/geometry", response_model=Geometry, responses=FOUND)
async def get_geometry(
    network_id: str, service: Annotated[FleetService, Depends(fleet_service)]
) -> dict[str, Any]:
    """GeoJSON of the usable edges, in the network's own coordinates."""
    entry = await run_in_threadpool(service.network, network_id)
    return await run_in_threadpool(entry.geometry)


@router.post(
    "/{network_id}/positions:resolve", response_model=ResolvedPositions, responses=WRITE | FOUND
)
async def resolve_positions(
    network_id: str,
    batch: PositionBatch,
    service: Annotated[FleetService, Depends(fleet_service)],
) -> dict[str, Any]:
    """Where each position lies on the network, as targets are resolved (an edge and offset,
    or the nearest usable edge within the snapping distance of an x/y or lon/lat point);
    a position that is not on it is listed with the reason. Changes nothing."""
    entry = await run_in_threadpool(service.network, network_id)

    def resolve() -> dict[str, Any]:
        positions: list[dict[str, Any] | None] = []
        unresolved: list[dict[str, Any]] = []
        for index, position in enumerate(batch.positions):
            try:
                positions.append(entry.describe(entry.resolve(position)))
            except (InvalidInput, NotFound, OffNetwork) as exc:
                positions.append(None)
                unresolved.append({"index": index, "detail": exc.detail})
        return {"positions": positions, "unresolved": unresolved}

    return await run_in_threadpool(resolve)
