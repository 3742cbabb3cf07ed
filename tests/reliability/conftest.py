"""Shared pieces of the reliability suite: scale, live servers, RSS, figures.

Everything is sized for CI (the whole folder in a few minutes on two shared
cores); ``ROUTING_SVC_SOAK_SCALE`` (default 1) multiplies counts and durations
for local soaks. The figures each test measured are printed at the end of the
run (``pytest_terminal_summary``), with or without ``-s``, and written as JSON.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from routing_svc.store import EventLog
from tests.service.conftest import DRT, LiveServer

SCALE = float(os.environ.get("ROUTING_SVC_SOAK_SCALE", "1"))
FIGURES: list[tuple[str, dict[str, Any]]] = []


def scaled(value: float) -> int:
    """``value`` times ``ROUTING_SVC_SOAK_SCALE``, at least 1."""
    return max(1, round(value * SCALE))


def record_figures(name: str, figures: dict[str, Any], directory: Path) -> None:
    """Keep ``figures`` for the end-of-run summary and write them to ``directory``."""
    FIGURES.append((name, figures))
    (directory / f"{name}.json").write_text(json.dumps(figures, indent=2))
    print(f"{name}: {json.dumps(figures)}")


def pytest_terminal_summary(terminalreporter: Any) -> None:
    if FIGURES:
        terminalreporter.section(f"reliability figures (ROUTING_SVC_SOAK_SCALE={SCALE})")
        for name, figures in FIGURES:
            terminalreporter.write_line(f"{name}: {json.dumps(figures)}")


def vm_kib(pid: int, field: str) -> int:
    """A ``/proc/PID/status`` field in KiB (``VmRSS``, ``VmHWM``)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise LookupError(field)


def replay(db_url: str, tmp_path: Path) -> dict[str, Any]:
    """``routing-svc replay --database-url URL``: must exit 0; its JSON report."""
    out = subprocess.run(
        [sys.executable, "-m", "routing_svc.cli", "replay", "--database-url", db_url,
         "--data-dir", str(tmp_path / "networks")],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    report: dict[str, Any] = json.loads(out.stdout)
    assert report["ok"] is True
    return report


def integrity(db_url: str) -> list[str]:
    """``EventLog.integrity_check()`` (SQLite ``integrity_check`` and seq gaps)."""
    with EventLog(db_url) as log:
        return log.integrity_check()


class Server(LiveServer):
    """A :class:`LiveServer` that keeps its port across restarts and takes extra options."""

    def __init__(
        self, db_url: str, tmp_path: Path, *, workers: int = 1, extra: tuple[str, ...] = ()
    ) -> None:
        super().__init__(db_url, tmp_path, workers=workers)
        self.extra = extra

    def start(self) -> Server:
        env = {**os.environ, "DATABASE_URL": self.db_url}
        cmd = [
            sys.executable, "-m", "routing_svc.cli", "serve",
            "--port", str(self.port), "--net", f"drt={DRT}", "--no-demo",
            "--workers", str(self.workers), "--data-dir", str(self.tmp_path / "networks"),
            "--log-level", "warning", *self.extra,
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
            time.sleep(0.05)
        raise RuntimeError(f"server did not start: {self.log.read_text()[-2000:]}")

    def kill(self, sig: int = signal.SIGKILL) -> None:
        assert self.process is not None
        os.killpg(self.process.pid, sig)
        self.process.wait(timeout=60)


@pytest.fixture
def sqlite_url(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'events.db'}"


@pytest.fixture
def server(sqlite_url: str, tmp_path: Path) -> Iterator[Callable[..., Server]]:
    """``server(workers=1, extra=())`` starts a live server on this test's SQLite file."""
    started: list[Server] = []

    def start(*, workers: int = 1, extra: tuple[str, ...] = ()) -> Server:
        s = Server(sqlite_url, tmp_path, workers=workers, extra=extra).start()
        started.append(s)
        return s

    yield start
    for s in started:
        s.stop()


def serial_replay(db_url: str, tmp_path: Path, fleet_id: str) -> dict[str, Any]:
    """The fleet as ``GET /v1/fleets/{id}`` shows it, rebuilt from its whole log, in order."""
    from routing_svc.service.app import load_networks
    from routing_svc.service.networks import NetworkRegistry
    from routing_svc.service.runtime import FleetRuntime
    from routing_svc.service.settings import Settings

    settings = Settings(database_url=db_url, data_dir=tmp_path / "networks")
    with EventLog(db_url) as log:
        registry = NetworkRegistry(data_dir=settings.data_dir, max_bytes=settings.max_network_bytes)
        load_networks(registry, log, settings)
        events = log.events_since(fleet_id, 0)
        entry = registry.get(log.get_fleet(fleet_id).network_id)
    runtime = FleetRuntime(
        fleet_id, entry, json.loads(events[0].payload_json), recent_window=settings.recent_window
    )
    for e in events[1:]:
        runtime.replay(e.seq, e.kind, e.payload_json, e.result_json)
    described: dict[str, Any] = json.loads(json.dumps(runtime.describe()))
    return described
