"""Every error as ``application/problem+json`` (RFC 9457), mapped in one place.

A client error (4xx) says what was wrong in its ``detail``. A server error (5xx)
never shows its cause (a driver's message names hosts, ports, SQL and library
links): its ``detail`` is a short fixed text of its class and it carries an
``error_id``; the server logs the full cause under the same id (logger
``routing_svc.errors``). A 503 caused by the store carries ``Retry-After``.
"""

from __future__ import annotations

import logging
import uuid
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from routing_svc import errors

PROBLEM = "application/problem+json"

STATUS: dict[type[errors.RoutingSvcError], int] = {
    errors.UnmetRequirement: 422,
    errors.InvalidInput: 422,
    errors.UnknownFleet: 404,
    errors.UnknownNetwork: 404,
    errors.UnknownEdge: 404,
    errors.UnknownVehicleType: 404,
    errors.NotFound: 404,
    errors.Unreachable: 422,
    errors.OffNetwork: 422,
    errors.InvalidNetwork: 422,
    errors.Conflict: 409,
    errors.PayloadTooLarge: 413,
    errors.StorageError: 503,
    errors.ReplayMismatch: 500,
}

TYPES: dict[type[errors.RoutingSvcError], str] = {
    errors.StorageError: "storage-unavailable",
    errors.StorageTimeout: "storage-timeout",
    errors.CommitOutcomeUnknown: "commit-outcome-unknown",
}
"""The problem ``type`` slug of classes whose title does not make it (the most specific wins)."""

PUBLIC_DETAIL: dict[type[BaseException], str] = {
    errors.StorageError: "The event store cannot serve this request now; retry later.",
    errors.StorageTimeout: (
        "The event store did not answer within the request's deadline; nothing was written."
    ),
    errors.CommitOutcomeUnknown: (
        "The write may or may not have been committed; retry with the same Idempotency-Key "
        "(a fleet's creation: the same body)."
    ),
    errors.ReplayMismatch: "The stored state of this fleet does not replay.",
    Exception: "An internal error occurred.",
}
"""The ``detail`` of each server error class (the most specific wins)."""

DEFAULT_RETRY_AFTER_S = 2
"""``Retry-After`` when the application has no settings (yet)."""

LOG = logging.getLogger("routing_svc.errors")


def status_of(error: errors.RoutingSvcError) -> int:
    """The HTTP status of a domain error (the most specific class wins)."""
    for cls in type(error).__mro__:
        if cls in STATUS:
            return STATUS[cls]
    return 500


def _most_specific(cls: type[BaseException], table: dict[Any, str]) -> str | None:
    for base in cls.__mro__:
        if base in table:
            return table[base]
    return None


def problem(status: int, title: str, detail: str, **extra: Any) -> JSONResponse:
    """A problem+json response."""
    slug = title.lower().replace(" ", "-")
    body = _document(status, title, detail, slug) | extra
    return JSONResponse(body, status_code=status, media_type=PROBLEM)


def retry_after_of(app: Any) -> int:
    """The application's ``Retry-After`` for store failures (its settings')."""
    settings = getattr(getattr(app, "state", None), "settings", None)
    return int(getattr(settings, "retry_after_s", DEFAULT_RETRY_AFTER_S))


def error_document(error: BaseException) -> dict[str, Any]:
    """The one mapping from an exception to its problem document.

    A domain error gets its status (:data:`STATUS`); anything else is a 500. A
    server error is logged with its cause under a fresh ``error_id`` and described
    by its class's fixed detail (:data:`PUBLIC_DETAIL`).
    """
    if isinstance(error, errors.RoutingSvcError):
        status, title = status_of(error), error.title
        slug = _most_specific(type(error), TYPES) or title.lower().replace(" ", "-")
        if status < 500:
            return _document(status, title, error.detail, slug) | error.problem_members()
    else:
        status, title, slug = 500, "Internal error", "internal-error"
    error_id = uuid.uuid4().hex
    LOG.error(
        "error_id=%s status=%s %s: %s",
        error_id,
        status,
        type(error).__name__,
        getattr(error, "detail", error),
        exc_info=error,
    )
    detail = _most_specific(type(error), PUBLIC_DETAIL) or PUBLIC_DETAIL[Exception]
    return _document(status, title, detail, slug) | {"error_id": error_id}


def _document(status: int, title: str, detail: str, slug: str) -> dict[str, Any]:
    return {
        "type": f"urn:routing-svc:problem:{slug}",
        "title": title,
        "status": status,
        "detail": detail,
    }


def error_problem(error: BaseException, *, retry_after: int) -> JSONResponse:
    """:func:`error_document` as a response; a 503 gets ``Retry-After``."""
    body = error_document(error)
    status = int(body["status"])
    headers = {"Retry-After": str(retry_after)} if status == 503 else None
    return JSONResponse(body, status_code=status, media_type=PROBLEM, headers=headers)


def _location(loc: tuple[Any, ...] | list[Any]) -> str:
    return ".".join(str(part) for part in loc if part not in ("body",)) or "body"


def install_problem_handlers(app: FastAPI) -> None:
    """Map domain errors, validation errors and HTTP errors to problem+json."""

    @app.exception_handler(errors.RoutingSvcError)
    async def domain_error(request: Request, exc: errors.RoutingSvcError) -> JSONResponse:
        return error_problem(exc, retry_after=retry_after_of(request.app))

    @app.exception_handler(Exception)
    async def unexpected_error(request: Request, exc: Exception) -> JSONResponse:
        return error_problem(exc, retry_after=retry_after_of(request.app))

    @app.exception_handler(RequestValidationError)
    async def validation_error(_: Request, exc: RequestValidationError) -> JSONResponse:
        issues = [
            {"field": _location(e.get("loc", ())), "message": str(e.get("msg", ""))}
            for e in exc.errors()
        ]
        detail = "; ".join(f"{i['field']}: {i['message']}" for i in issues[:5])
        return problem(422, "Invalid input", detail, errors=issues)

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        title = {404: "Not found", 405: "Method not allowed", 401: "Unauthorized"}.get(
            exc.status_code, "HTTP error"
        )
        response = problem(exc.status_code, title, str(exc.detail))
        response.headers.update(exc.headers or {})
        if exc.status_code == 405:
            response.headers["Allow"] = allowed_methods(request)
        return response


METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE")
"""The methods a 405's ``Allow`` may name."""


def allowed_methods(request: Request) -> str:
    """The ``Allow`` header of a 405 (RFC 9110, section 15.5.6): every method some route
    of the application takes on the request's path (the router names only the first
    route's)."""
    routes = request.app.router.routes
    allowed = [
        method
        for method in METHODS
        if any(
            route.matches({**request.scope, "type": "http", "method": method})[0] == Match.FULL
            for route in routes
        )
    ]
    return ", ".join(allowed)
