"""Fixtures for the service tests: an app on each database backend, a live server."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from routing_svc.service.app import create_app
from tests.helpers import LiveServer, make_settings


@pytest.fixture
def client(db_url: str, tmp_path: Path) -> Iterator[TestClient]:
    """The app on a fresh database of each backend, with the DRT network loaded."""
    with TestClient(create_app(make_settings(db_url, tmp_path))) as c:
        yield c


@pytest.fixture
def make_client(tmp_path: Path) -> Iterator[Callable[..., TestClient]]:
    """``make_client(db_url, **settings)``: an app with extra settings (closed afterwards)."""
    opened: list[TestClient] = []

    def build(db_url: str, **extra: object) -> TestClient:
        c = TestClient(create_app(make_settings(db_url, tmp_path, **extra)))
        c.__enter__()
        opened.append(c)
        return c

    yield build
    for c in opened:
        c.__exit__(None, None, None)


@pytest.fixture
def live_server(db_url: str, tmp_path: Path) -> Iterator[Callable[..., LiveServer]]:
    """``live_server(workers=1)`` starts a server on this test's database."""
    servers: list[LiveServer] = []

    def start(*, workers: int = 1) -> LiveServer:
        server = LiveServer(db_url, tmp_path, workers=workers).start()
        servers.append(server)
        return server

    yield start
    for server in servers:
        server.stop()
