"""Driving the dashboard in headless Chromium (Debian's ``chromium``) with Playwright."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from playwright.sync_api import ConsoleMessage, Page, Request, Route

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
VIEWPORT = {"width": 1440, "height": 900}
LIVE_UPDATE_MS = 2000
"""The issue's bound: a posted target shows on the page within 2 seconds."""
LOAD_MS = 15000


class DashboardPage:
    """One browser page on the dashboard of a live server, recording what went wrong.

    Every request that leaves the server's origin is refused and recorded, so a
    test can show that the page works offline (no CDN, no tiles).
    """

    def __init__(self, page: Page, base_url: str, shots: Path) -> None:
        self.page = page
        self.base_url = base_url
        self.shots = shots
        self.console_errors: list[str] = []
        self.external_requests: list[str] = []
        self.failed_requests: list[str] = []
        page.on("console", self._on_console)
        page.on("pageerror", lambda error: self.console_errors.append(f"pageerror: {error}"))
        page.on("requestfailed", self._on_failed)
        page.on("response", self._on_response)
        page.route("**/*", self._only_own_origin)

    def _on_console(self, message: ConsoleMessage) -> None:
        if message.type == "error":
            self.console_errors.append(message.text)

    def _on_failed(self, request: Request) -> None:
        failure = request.failure or ""
        # EventSource connections are aborted when the page goes away; that is not a failure.
        if "ERR_ABORTED" not in failure:
            self.failed_requests.append(f"{request.url}: {failure}")

    def _on_response(self, response: Any) -> None:
        if response.status >= 400:
            self.failed_requests.append(f"{response.url}: HTTP {response.status}")

    def _only_own_origin(self, route: Route) -> None:
        url = route.request.url
        if url.startswith(self.base_url) or url.startswith("data:"):
            route.continue_()
        else:
            self.external_requests.append(url)
            route.abort()

    # -- navigation -------------------------------------------------------------

    def open(self, fleet: str | None = None, *, state: str = "ready") -> DashboardPage:
        """Load the dashboard (optionally on a fleet) and wait until it shows ``state``."""
        query = f"?fleet={fleet}" if fleet else ""
        self.page.goto(f"{self.base_url}/dashboard{query}")
        self.wait_state(state)
        if state == "ready":
            self.page.wait_for_selector("#live-status[data-live='open']", timeout=LOAD_MS)
        return self

    def wait_state(self, state: str, *, timeout: float = LOAD_MS) -> None:
        self.page.wait_for_selector(f"body[data-state='{state}']", timeout=timeout)

    def screenshot(self, name: str) -> Path:
        path = self.shots / f"{name}.png"
        self.page.screenshot(path=path)
        return path

    # -- what the page shows ----------------------------------------------------

    def vehicles(self) -> dict[str, dict[str, Any]]:
        """Every vehicle marker: network coordinates, SVG centre, type and screen centre."""
        rows: list[dict[str, Any]] = self.page.eval_on_selector_all(
            "circle.vehicle",
            """circles => circles.map(c => {
                const box = c.getBoundingClientRect();
                const ctm = c.ownerSVGElement.getScreenCTM();
                const p = new DOMPoint(Number(c.getAttribute('cx')), Number(c.getAttribute('cy')))
                    .matrixTransform(ctm);
                return {
                    id: c.dataset.vehicle, type: c.dataset.type,
                    x: Number(c.dataset.x), y: Number(c.dataset.y),
                    cx: Number(c.getAttribute('cx')), cy: Number(c.getAttribute('cy')),
                    screen: [box.x + box.width / 2, box.y + box.height / 2],
                    projected: [p.x, p.y],
                    fill: c.getAttribute('fill'),
                    stroke: c.getAttribute('stroke'),
                    status: c.dataset.status,
                };
            })""",
        )
        return {row["id"]: row for row in rows}

    def screen_point(self, x: float, y: float) -> tuple[float, float]:
        """Where the network point ``(x, y)`` is on the screen (page coordinates)."""
        point: list[float] = self.page.evaluate(
            """([x, y]) => {
                const svg = document.querySelector('#map');
                const p = new DOMPoint(x, -y).matrixTransform(svg.getScreenCTM());
                return [p.x, p.y];
            }""",
            [x, y],
        )
        return point[0], point[1]

    def map_box(self) -> tuple[float, float, float, float]:
        """The map's ``left, top, width, height`` on screen, in CSS pixels."""
        box: list[float] = self.page.eval_on_selector(
            "#map",
            "e => { const r = e.getBoundingClientRect();"
            " return [r.left, r.top, r.width, r.height]; }",
        )
        return box[0], box[1], box[2], box[3]

    def view_box(self) -> list[float]:
        text: str = self.page.get_attribute("#map", "viewBox") or ""
        return [float(v) for v in text.split()]

    def wait_vehicle_at(self, vehicle: str, x: float, y: float, *, timeout: float) -> None:
        """Wait until the marker of ``vehicle`` is exactly at network point ``(x, y)``."""
        self.page.wait_for_function(
            """([id, x, y]) => {
                const c = document.querySelector(`circle.vehicle[data-vehicle="${id}"]`);
                return c !== null && Number(c.dataset.x) === x && Number(c.dataset.y) === y
                    && Number(c.getAttribute('cx')) === x && Number(c.getAttribute('cy')) === -y;
            }""",
            arg=[vehicle, x, y],
            timeout=timeout,
        )

    def problems(self) -> dict[str, list[str]]:
        """Console errors, failed requests and refused external requests (all should be empty)."""
        return {
            "console_errors": list(self.console_errors),
            "failed_requests": list(self.failed_requests),
            "external_requests": list(self.external_requests),
        }
