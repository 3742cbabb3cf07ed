"""Fixtures for the service tests: an app on each database backend, a live server."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from routing_svc.network.catalogue import resolve_network
from routing_svc.service.app import create_app
from routing_svc.service.settings import Settings

DRT = str(resolve_network("drt"))


def make_settings(db_url: str, tmp_path: Path, **extra: object) -> Settings:
    return Settings(
        database_url=db_url,
        networks={"drt": DRT},
        data_dir=tmp_path / "networks",
        **extra,  # type: ignore[arg-type]
    )


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


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


class LiveServer:
    """``routing-svc serve`` in a subprocess (real uvicorn, real sockets)."""

    def __init__(self, db_url: str, tmp_path: Path, *, workers: int = 1) -> None:
        self.db_url = db_url
        self.tmp_path = tmp_path
        self.workers = workers
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.process: subprocess.Popen[bytes] | None = None
        self.log = tmp_path / f"server-{self.port}.log"

    def start(self) -> LiveServer:
        env = {**os.environ, "DATABASE_URL": self.db_url}
        cmd = [
            sys.executable, "-m", "routing_svc.cli", "serve",
            "--port", str(self.port), "--net", f"drt={DRT}", "--no-demo",
            "--workers", str(self.workers), "--data-dir", str(self.tmp_path / "networks"),
            "--log-level", "warning",
        ]  # fmt: skip
        with self.log.open("ab") as out:
            self.process = subprocess.Popen(
                cmd, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
            )
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"server exited: {self.log.read_text()[-2000:]}")
            try:
                if httpx.get(self.url + "/healthz", timeout=1.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        raise RuntimeError(f"server did not start: {self.log.read_text()[-2000:]}")

    def kill(self, sig: int = signal.SIGKILL) -> None:
        assert self.process is not None
        os.killpg(self.process.pid, sig)
        self.process.wait(timeout=30)

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.kill(signal.SIGTERM)


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
