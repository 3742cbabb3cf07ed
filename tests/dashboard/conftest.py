"""Fixtures of the dashboard tests: live servers, headless Chromium, a dashboard page.

The browser tests run on SQLite only (fast); the stream tests also run on
PostgreSQL through the shared ``db_url`` fixture.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Browser, sync_playwright

from tests.dashboard.browser import CHROMIUM, CHROMIUM_ARGS, VIEWPORT, DashboardPage
from tests.dashboard.service_client import ServiceClient
from tests.helpers import LiveServer


@pytest.fixture(scope="module")
def shared_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """One server on SQLite for a test module; each test makes fleets of its own."""
    folder = tmp_path_factory.mktemp("server")
    server = LiveServer(f"sqlite:///{folder / 'events.db'}", folder).start()
    yield server
    server.stop()


@pytest.fixture
def empty_server(tmp_path: Path) -> Iterator[LiveServer]:
    """A server on a new SQLite database: no fleets at all."""
    server = LiveServer(f"sqlite:///{tmp_path / 'events.db'}", tmp_path).start()
    yield server
    server.stop()


@pytest.fixture
def connect() -> Iterator[Callable[[LiveServer], ServiceClient]]:
    """``connect(server)``: an API client of a server (closed after the test)."""
    clients: list[ServiceClient] = []

    def make(server: LiveServer) -> ServiceClient:
        clients.append(ServiceClient(server.url))
        return clients[-1]

    yield make
    for client in clients:
        client.close()


@pytest.fixture
def api(shared_server: LiveServer, connect: Callable[[LiveServer], ServiceClient]) -> ServiceClient:
    """An API client of the module's shared server."""
    return connect(shared_server)


@pytest.fixture
def fleet_id() -> str:
    """A fleet id of this test's own."""
    return f"f-{uuid.uuid4().hex[:10]}"


@pytest.fixture(scope="session")
def browser() -> Iterator[Browser]:
    """Headless Chromium from Debian's ``chromium`` package (no downloads)."""
    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield chromium
        chromium.close()


@pytest.fixture
def open_dashboard(
    browser: Browser, tmp_path: Path
) -> Iterator[Callable[[LiveServer], DashboardPage]]:
    """``open_dashboard(server)``: a fresh page on the server's dashboard (not loaded yet).

    Screenshots go to this test's ``tmp_path``.
    """
    contexts = []

    def make(server: LiveServer) -> DashboardPage:
        context = browser.new_context(viewport=VIEWPORT)  # type: ignore[arg-type]
        contexts.append(context)
        return DashboardPage(context.new_page(), server.url, tmp_path)

    yield make
    for context in contexts:
        context.close()
