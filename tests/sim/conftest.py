"""Shared co-simulations on a small generated network (real SUMO through libsumo).

Each experiment runs once per test session and is shared by the tests that
only read its results: the ``grid`` network (6x6 junctions, 200 m blocks,
generated with netgenerate), 4 vehicles, 15 simulated minutes of requests.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import httpx
import pytest

from routing_svc.network.catalogue import resolve_network
from routing_svc.sim import CosimResult, CosimSpec, parse_policies, run_cosim

ALL_POLICIES = (
    "sa,sa-available,sa-cold,static,optimum,sumo-stop,sumo-closest,sumo-circling,sumo-taxistand"
)


@pytest.fixture(scope="session")
def grid_net(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The generated ``grid`` network, made in this session's temporary folder."""
    return resolve_network("grid", out_dir=tmp_path_factory.mktemp("nets"))


@pytest.fixture(scope="session")
def small_spec(grid_net: Path) -> CosimSpec:
    """Persons on the grid: every policy, one seed, a few simulated minutes.

    The fleets learn by the paper's rule, whose every update moves a reference: a
    few minutes bring too few requests for the default rule's held steps to move one.
    """
    return CosimSpec(
        network=str(grid_net),
        mode="persons",
        vehicles=4,
        duration=900.0,
        warmup=120.0,
        drain=300.0,
        rate=60.0,
        demand="hotspots:2",
        history=200,
        density=20.0,
        policies=parse_policies(ALL_POLICIES),
        seeds=(3,),
        workers=1,
        rule="paper",
    )


@pytest.fixture(scope="session")
def persons_result(small_spec: CosimSpec, tmp_path_factory: pytest.TempPathFactory) -> CosimResult:
    return run_cosim(small_spec, out_dir=tmp_path_factory.mktemp("persons"), progress=False)


@pytest.fixture(scope="session")
def incidents_result(
    small_spec: CosimSpec, tmp_path_factory: pytest.TempPathFactory
) -> CosimResult:
    spec = replace(
        small_spec,
        mode="incidents",
        policies=parse_policies("sa,static,optimum,sumo-stop,sumo-circling"),
        history=50,
        incident_sample=300,
        workers=2,
    )
    return run_cosim(spec, out_dir=tmp_path_factory.mktemp("incidents"), progress=False)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@contextmanager
def serve_fleets(networks: dict[str, Path], folder: Path) -> Iterator[str]:
    """The REST service (``create_app`` under uvicorn, in a thread) started with
    ``networks`` (as ``serve --net NAME=FILE``); its URL."""
    import uvicorn

    from routing_svc.service.app import create_app
    from routing_svc.service.settings import Settings

    settings = Settings(
        database_url=f"sqlite:///{folder / 'service.db'}",
        networks={name: str(path) for name, path in networks.items()},
        data_dir=folder / "networks",
    )
    port = _free_port()
    server = uvicorn.Server(
        uvicorn.Config(create_app(settings), host="127.0.0.1", port=port, log_level="warning")
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while not server.started:
            if not thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("the fleet service did not start")
            time.sleep(0.05)
        assert httpx.get(url + "/healthz", timeout=5.0).status_code == 200
        yield url
    finally:
        server.should_exit = True
        thread.join(timeout=30)


@pytest.fixture
def fleet_server(grid_net: Path, tmp_path: Path) -> Iterator[str]:
    """The REST service with the grid; its URL."""
    with serve_fleets({"grid": grid_net}, tmp_path) as url:
        yield url
