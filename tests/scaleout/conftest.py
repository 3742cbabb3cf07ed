"""Fixtures for the scale-out tests: several service processes on one PostgreSQL schema."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from tests.conftest import pg_url
from tests.helpers import LiveServer


@pytest.fixture
def shared_pg_url(pg_database: str, pg_schema: str) -> str:
    """A fresh PostgreSQL schema that every instance of the test shares."""
    return pg_url(pg_database, schema=pg_schema)


@pytest.fixture
def instances(shared_pg_url: str, tmp_path: Path) -> Iterator[Callable[[int], list[LiveServer]]]:
    """``instances(n)``: ``n`` ``routing-svc serve`` processes on one schema, started at once.

    They start concurrently (as ``docker compose up --scale service=n`` does on a
    fresh database), so the start-up path must tolerate a peer migrating the
    schema and registering the same network at the same moment.
    """
    started: list[LiveServer] = []

    def start(n: int) -> list[LiveServer]:
        servers = [LiveServer(shared_pg_url, tmp_path) for _ in range(n)]
        started.extend(servers)
        with ThreadPoolExecutor(n) as pool:
            list(pool.map(LiveServer.start, servers))
        return servers

    yield start
    for server in started:
        server.stop()
