"""The dashboard: ``GET /dashboard`` (one HTML page), its static assets, and ``GET /``.

Everything the page needs ships inside the package under ``service/static/``:
no CDN, no map tiles, no web fonts, so the dashboard works offline. A strict
``Content-Security-Policy`` on the page makes the browser refuse anything that
is not served from this origin, so an accidental external reference fails
loudly (in the browser console) instead of silently phoning home.

Assets are served from a fixed table built from the package's files, never
from a path assembled out of the request, so no request can reach a file
outside ``static/``. Browsers revalidate them by ``ETag`` on every load, so an
upgraded package never runs with a stale script.
"""

from __future__ import annotations

import hashlib
import html
import mimetypes
from functools import cache
from importlib import resources
from importlib.resources.abc import Traversable

from fastapi import APIRouter, Request, Response
from fastapi.responses import HTMLResponse, RedirectResponse

from routing_svc.errors import NotFound

router = APIRouter(tags=["dashboard"], include_in_schema=False)

STATIC_PACKAGE = "routing_svc.service"
STATIC_DIR = "static"
BASE_PLACEHOLDER = "%BASE%"

CONTENT_SECURITY_POLICY = "; ".join(
    [
        "default-src 'self'",
        "script-src 'self'",
        "style-src 'self'",
        "img-src 'self' data:",
        "connect-src 'self'",
        "font-src 'self'",
        "object-src 'none'",
        "base-uri 'none'",
        "frame-ancestors 'none'",
        "form-action 'none'",
    ]
)

MEDIA_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".svg": "image/svg+xml",
    ".png": "image/png",
}


def _walk(node: Traversable, prefix: str) -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    for child in node.iterdir():
        name = f"{prefix}{child.name}"
        if child.is_dir():
            out.update(_walk(child, f"{name}/"))
        elif child.is_file() and not child.name.startswith("."):
            out[name] = child.read_bytes()
    return out


@cache
def static_assets() -> dict[str, bytes]:
    """Every file under ``service/static/`` by its relative path (read once)."""
    root = resources.files(STATIC_PACKAGE).joinpath(STATIC_DIR)
    return _walk(root, "")


@cache
def etag(body: bytes) -> str:
    """A strong validator of an asset's bytes."""
    return '"' + hashlib.sha256(body).hexdigest()[:32] + '"'


def media_type(name: str) -> str:
    """The ``Content-Type`` of an asset, from its suffix."""
    suffix = name[name.rfind(".") :] if "." in name else ""
    return MEDIA_TYPES.get(suffix) or mimetypes.guess_type(name)[0] or "application/octet-stream"


def base_path(request: Request) -> str:
    """The path prefix the service is mounted under (``root_path``), without a trailing slash."""
    root: str = request.scope.get("root_path", "")
    return root.rstrip("/")


@router.get("/")
async def index(request: Request) -> RedirectResponse:
    """The service's home is the dashboard."""
    return RedirectResponse(f"{base_path(request)}/dashboard", status_code=307)


@router.get("/dashboard", response_class=HTMLResponse)
async def dashboard(request: Request) -> HTMLResponse:
    """The dashboard page: map, live fleet, charts and a target panel."""
    page = static_assets()["index.html"].decode("utf-8")
    page = page.replace(BASE_PLACEHOLDER, html.escape(base_path(request), quote=True))
    return HTMLResponse(
        page,
        headers={
            "Content-Security-Policy": CONTENT_SECURITY_POLICY,
            "Cache-Control": "no-cache",
            "X-Content-Type-Options": "nosniff",
            "Referrer-Policy": "no-referrer",
        },
    )


@router.get("/dashboard/static/{name:path}")
async def dashboard_asset(request: Request, name: str) -> Response:
    """A stylesheet or script of the dashboard, revalidated by its ``ETag`` on each use."""
    body = static_assets().get(name)
    if body is None or name == "index.html":
        raise NotFound(f"no dashboard asset {name!r}")
    tag = etag(body)
    headers = {"ETag": tag, "Cache-Control": "no-cache", "X-Content-Type-Options": "nosniff"}
    if tag in request.headers.get("if-none-match", ""):
        return Response(status_code=304, headers=headers)
    return Response(body, media_type=media_type(name), headers=headers)
