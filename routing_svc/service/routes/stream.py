"""``GET /v1/fleets/{id}/stream``: a fleet's event log as Server-Sent Events.

Each connection polls the event log every :data:`POLL_SECONDS` instead of
waiting for an in-process notification, so a client connected to any uvicorn
worker on any host sees every event, whichever worker or host wrote it. The
stream sends

- ``event: log`` for every stored event, ``id:`` its ``seq`` and ``data:``
  ``{"seq", "kind", "created_at", "result"}`` (a target's ``result`` is the
  answer its poster got: ``served_by``, ``moved``, ``new_position``,
  ``target``, ``requires``, ``cost``, ``step_size`` ...);
- ``event: metrics`` with ``GET /v1/fleets/{id}/metrics``, first at once and
  then after new events, at most every :data:`METRICS_SECONDS`; its
  ``service_levels`` hold the fraction of targets completed within each of the
  fleet's thresholds and the completion cost's percentiles, over all targets
  and the recent window (a ``vehicle_state`` event's ``result`` lists the
  vehicles it changed, a target's its ``dispatch`` answer);
- ``event: problem`` (a problem document) when the stream cannot go on;
- a comment line every :data:`KEEPALIVE_SECONDS` when nothing else was sent.

Where the stream starts: after ``Last-Event-ID`` (what ``EventSource`` sends
when it reconnects), else after ``?after=SEQ``, else after the fleet's current
version (only new events). A ``fleet_deleted`` event ends the stream.

A stream ends on its own: when the client disconnects, when the server is
shutting down, and after :data:`LIFETIME_SECONDS` at the latest (the client
reconnects and resumes from its last event id, losing nothing). uvicorn waits
for open responses before it runs the application's shutdown, so without
these bounds one open dashboard would keep a server from exiting on SIGTERM.
"""

from __future__ import annotations

import asyncio
import json
import re
import signal
from collections.abc import AsyncGenerator, AsyncIterator
from contextlib import aclosing
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Header, Query, Request
from fastapi.responses import StreamingResponse
from prometheus_client import Gauge
from starlette.concurrency import run_in_threadpool

from routing_svc.errors import InvalidInput, RoutingSvcError, UnknownFleet
from routing_svc.service.deps import fleet_service
from routing_svc.service.fleets import FleetService
from routing_svc.service.problems import error_document
from routing_svc.service.responses import FOUND, INVALID, READ
from routing_svc.store import EventRecord

POLL_SECONDS = 0.25
"""How often a stream looks for new events."""
PAGE_SIZE = 500
"""Events read per poll; a full page is followed by another read at once."""
METRICS_SECONDS = 1.0
"""Least time between two metrics messages."""
KEEPALIVE_SECONDS = 15.0
"""Longest silence before a comment line (keeps proxies from closing the stream)."""
LIFETIME_SECONDS = 60.0
"""Longest life of one stream; the client reconnects from its last event id."""
RETRY_MS = 1000
"""How long ``EventSource`` waits before reconnecting."""
MAX_SEQ = 2**62


def decimal_at_most(limit: int) -> str:
    """A regular expression of the decimal numbers from 0 to ``limit``, leading zeros
    allowed up to the length of ``limit``, or nothing: ``Last-Event-ID``'s values in
    the OpenAPI document (:func:`resume_point` reads them)."""
    text = str(limit)
    same_length = [
        f"{text[:i]}[0-{int(digit) - 1}][0-9]{{{len(text) - i - 1}}}"
        for i, digit in enumerate(text)
        if digit != "0"
    ]
    shorter = f"[0-9]{{1,{len(text) - 1}}}"
    return "^(|" + "|".join([shorter, *same_length, text]) + ")$"


LAST_EVENT_ID = decimal_at_most(MAX_SEQ)

STREAMS_OPEN = Gauge("routing_svc_sse_streams", "Server-Sent Events streams open in this process")

router = APIRouter(prefix="/v1/fleets/{fleet_id}", tags=["stream"])
Service = Annotated[FleetService, Depends(fleet_service)]

STREAM_RESPONSE: dict[int | str, dict[str, Any]] = (
    {
        200: {
            "description": "Server-Sent Events: `log` (one per stored event), `metrics`, "
            "`problem`.",
            "content": {
                "text/event-stream": {
                    "schema": {
                        "type": "object",
                        "description": "One message of the stream.",
                        "properties": {
                            "event": {"enum": ["log", "metrics", "problem"]},
                            "data": {"type": "string", "description": "One line of JSON."},
                            "id": {"type": "string", "description": "The event's `seq` (`log`)."},
                            "retry": {"type": "integer", "minimum": 0},
                        },
                    }
                }
            },
        }
    }
    | READ
    | FOUND
    | INVALID
)


def sse_message(*, data: str, event: str | None = None, event_id: int | None = None) -> str:
    """One message in the ``text/event-stream`` format (``data`` is one line of JSON)."""
    lines = []
    if event is not None:
        lines.append(f"event: {event}")
    if event_id is not None:
        lines.append(f"id: {event_id}")
    lines.append(f"data: {data}")
    return "\n".join(lines) + "\n\n"


def log_message(event: EventRecord) -> str:
    """An event of the log as an ``event: log`` message (the payload is left out)."""
    body = {
        "seq": event.seq,
        "kind": event.kind,
        "created_at": event.created_at.isoformat(),
        "result": None if event.result_json is None else json.loads(event.result_json),
    }
    return sse_message(data=json.dumps(body, allow_nan=False), event="log", event_id=event.seq)


def problem_message(error: RoutingSvcError) -> str:
    """A domain error as an ``event: problem`` message (RFC 9457 fields)."""
    return sse_message(data=json.dumps(error_document(error)), event="problem")


async def metrics_message(service: FleetService, fleet_id: str) -> str | None:
    """The fleet's metrics as an ``event: metrics`` message, or ``None`` (no sample now).

    A fleet deleted since the last poll has no metrics but still has a
    ``fleet_deleted`` event to send: the next poll sends it and ends the stream.
    """
    try:
        metrics = await run_in_threadpool(service.metrics, fleet_id)
        data = json.dumps(metrics, allow_nan=False)
    except (UnknownFleet, ValueError):  # deleted, or not valid JSON (NaN): skip this sample
        return None
    return sse_message(data=data, event="metrics")


def server_is_exiting() -> bool:
    """Whether the uvicorn server of this process was asked to exit (SIGTERM, SIGINT).

    uvicorn installs its ``Server.handle_exit`` as the process's signal handler
    and sets ``Server.should_exit`` when a signal arrives, but it only tells the
    application about the shutdown after every open response has finished. This
    reads that flag through the installed handler; under another server it is
    simply ``False`` and :data:`LIFETIME_SECONDS` bounds the wait instead.
    """
    handler = signal.getsignal(signal.SIGTERM)
    server = getattr(handler, "__self__", None)
    return bool(getattr(server, "should_exit", False))


def resume_point(after: int | None, last_event_id: str | None) -> int | None:
    """The ``seq`` to stream after: ``Last-Event-ID`` wins over ``?after=``."""
    if last_event_id is not None and last_event_id.strip():
        text = last_event_id.strip()
        if not re.fullmatch(r"[0-9]{1,19}", text) or int(text) > MAX_SEQ:
            raise InvalidInput(f"Last-Event-ID must be an event seq, got {text!r}")
        return int(text)
    return after


async def fleet_events(
    request: Request, service: FleetService, fleet_id: str, after: int
) -> AsyncIterator[str]:
    """The messages of one stream (see the module docstring); ends on its own."""
    STREAMS_OPEN.inc()
    try:
        async with aclosing(_poll(request, service, fleet_id, after)) as messages:
            async for message in messages:
                yield message
    finally:
        STREAMS_OPEN.dec()


async def _poll(
    request: Request, service: FleetService, fleet_id: str, after: int
) -> AsyncGenerator[str, None]:
    """Poll the log until the stream should end: disconnect, shutdown, lifetime, deletion."""
    loop = asyncio.get_running_loop()
    started = loop.time()
    last_sent = started
    metrics_due = started
    metrics_seq = -1
    seq = after
    yield f"retry: {RETRY_MS}\n\n"
    while True:
        now = loop.time()
        if now - started >= LIFETIME_SECONDS or server_is_exiting():
            return
        if await request.is_disconnected():
            return
        try:
            events = await run_in_threadpool(
                service.log.events, fleet_id, after=seq, limit=PAGE_SIZE
            )
            for event in events:
                yield log_message(event)
                seq = event.seq
                last_sent = loop.time()
                if event.kind == "fleet_deleted":
                    return
            if seq != metrics_seq and loop.time() >= metrics_due:
                metrics_seq = seq
                metrics_due = loop.time() + METRICS_SECONDS
                message = await metrics_message(service, fleet_id)
                if message is not None:
                    yield message
                    last_sent = loop.time()
        except RoutingSvcError as error:  # the fleet is gone, the database is away, ...
            yield problem_message(error)
            return
        if loop.time() - last_sent >= KEEPALIVE_SECONDS:
            yield ": keep-alive\n\n"
            last_sent = loop.time()
        if len(events) < PAGE_SIZE:
            await asyncio.sleep(POLL_SECONDS)


@router.get("/stream", response_class=StreamingResponse, responses=STREAM_RESPONSE)
async def stream_fleet(
    fleet_id: str,
    request: Request,
    service: Service,
    after: Annotated[int | None, Query(ge=0, le=MAX_SEQ)] = None,
    last_event_id: Annotated[str | None, Header(max_length=32, pattern=LAST_EVENT_ID)] = None,
) -> StreamingResponse:
    """Live events and metrics of a fleet as Server-Sent Events (see the module docstring)."""
    start = resume_point(after, last_event_id)
    record = await run_in_threadpool(service.log.get_fleet, fleet_id)
    return StreamingResponse(
        fleet_events(request, service, fleet_id, record.version if start is None else start),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )
