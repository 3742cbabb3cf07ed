"""Fixtures of the history tests: the DRT district (it has a geographic projection),
calls written by the tests themselves, an in-process client, a live server."""

from __future__ import annotations

import csv
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from routing_svc.history import InProcessHistoryClient
from routing_svc.network import CompiledNetwork, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.network.snapping import point_on_edge

DRT = resolve_network("drt")


@pytest.fixture(scope="session")
def drt() -> CompiledNetwork:
    return load_network(DRT)


def random_calls(net: CompiledNetwork, n: int, *, seed: int) -> list[dict[str, Any]]:
    """``n`` calls at random positions: time (seconds), edge, offset, x, y, lon, lat."""
    rng = np.random.default_rng(seed)
    calls = []
    for i in range(n):
        e = int(rng.integers(net.n_edges))
        offset = round(float(rng.uniform(0.0, net.length[e])), 2)
        x, y = point_on_edge(net, e, offset)
        assert net.projection is not None
        lon, lat = net.projection.point_to_lonlat(x, y)
        calls.append(
            {"time": float(rng.uniform(0, 86_400)), "edge": net.edge_ids[e], "offset": offset,
             "x": x, "y": y, "lon": lon, "lat": lat, "i": i}
        )  # fmt: skip
    return calls


def write_csv(path: Path, header: Sequence[str], rows: Sequence[Sequence[object]]) -> Path:
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def write_edge_calls(path: Path, calls: Sequence[dict[str, Any]]) -> Path:
    """``calls`` (of :func:`random_calls`) as a ``time,edge,offset`` CSV file."""
    return write_csv(
        path, ["time", "edge", "offset"], [[c["time"], c["edge"], c["offset"]] for c in calls]
    )


@pytest.fixture
def client(tmp_path: Path) -> Iterator[InProcessHistoryClient]:
    """An in-process client on a fresh SQLite event log, with the DRT network."""
    c = InProcessHistoryClient(database_url=f"sqlite:///{tmp_path / 'events.db'}")
    c.add_network(DRT, name="drt")
    yield c
    c.close()


def fleet_at(
    edges: Sequence[tuple[str, float]], *, fleet_id: str = "f", rule: str = "paper"
) -> dict[str, Any]:
    """A fleet spec on ``drt`` with one vehicle at each ``(edge, offset)``."""
    return {
        "id": fleet_id,
        "network": "drt",
        "rule": rule,
        "vehicles": [
            {"id": f"v{i}", "position": {"edge": e, "offset": o}} for i, (e, o) in enumerate(edges)
        ],
    }


def cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "routing_svc.cli", *args],
        capture_output=True, text=True, timeout=600, env={**os.environ, **(env or {})},
    )  # fmt: skip


class LiveServers:
    """``routing-svc serve`` (uvicorn) processes on one SQLite file: calling the object
    starts one and answers its URL; :meth:`kill` ends the newest with SIGKILL."""

    def __init__(self, tmp_path: Path) -> None:
        self.tmp_path = tmp_path
        self.processes: list[subprocess.Popen[bytes]] = []

    def __call__(self) -> str:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        url = f"http://127.0.0.1:{port}"
        tmp_path = self.tmp_path
        cmd = [
            sys.executable, "-m", "routing_svc.cli", "serve", "--port", str(port),
            "--net", f"drt={DRT}", "--no-demo", "--db", str(tmp_path / "server.db"),
            "--data-dir", str(tmp_path / "networks"), "--log-level", "warning",
        ]  # fmt: skip
        with (tmp_path / "server.log").open("ab") as log:
            process = subprocess.Popen(
                cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
            )
        self.processes.append(process)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            assert process.poll() is None, (tmp_path / "server.log").read_text()
            try:
                if httpx.get(url + "/healthz", timeout=1.0).status_code == 200:
                    return url
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        raise RuntimeError("the server did not start")

    def kill(self) -> None:
        process = self.processes[-1]
        process.kill()
        process.wait(timeout=30)

    def stop_all(self) -> None:
        for process in self.processes:
            process.terminate()
            process.wait(timeout=30)


@pytest.fixture
def live_server(tmp_path: Path) -> Iterator[LiveServers]:
    """Start ``routing-svc serve`` on a fresh SQLite file (:class:`LiveServers`)."""
    servers = LiveServers(tmp_path)
    yield servers
    servers.stop_all()
