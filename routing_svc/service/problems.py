"""Every error as ``application/problem+json`` (RFC 9457), mapped in one place."""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

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


def status_of(error: errors.RoutingSvcError) -> int:
    """The HTTP status of a domain error (the most specific class wins)."""
    for cls in type(error).__mro__:
        if cls in STATUS:
            return STATUS[cls]
    return 500


def problem(status: int, title: str, detail: str, **extra: Any) -> JSONResponse:
    """A problem+json response."""
    slug = title.lower().replace(" ", "-")
    body = {"type": f"urn:routing-svc:problem:{slug}", "title": title, "status": status}
    body["detail"] = detail
    body.update(extra)
    return JSONResponse(body, status_code=status, media_type=PROBLEM)


def _location(loc: tuple[Any, ...] | list[Any]) -> str:
    return ".".join(str(part) for part in loc if part not in ("body",)) or "body"


def install_problem_handlers(app: FastAPI) -> None:
    """Map domain errors, validation errors and HTTP errors to problem+json."""

    @app.exception_handler(errors.RoutingSvcError)
    async def domain_error(_: Request, exc: errors.RoutingSvcError) -> JSONResponse:
        return problem(status_of(exc), exc.title, exc.detail, **exc.problem_members())

    @app.exception_handler(RequestValidationError)
    async def validation_error(_: Request, exc: RequestValidationError) -> JSONResponse:
        issues = [
            {"field": _location(e.get("loc", ())), "message": str(e.get("msg", ""))}
            for e in exc.errors()
        ]
        detail = "; ".join(f"{i['field']}: {i['message']}" for i in issues[:5])
        return problem(422, "Invalid input", detail, errors=issues)

    @app.exception_handler(StarletteHTTPException)
    async def http_error(_: Request, exc: StarletteHTTPException) -> JSONResponse:
        title = {404: "Not found", 405: "Method not allowed", 401: "Unauthorized"}.get(
            exc.status_code, "HTTP error"
        )
        return problem(exc.status_code, title, str(exc.detail))
