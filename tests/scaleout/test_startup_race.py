"""Instances starting at the same time on a fresh database register the same network."""

from __future__ import annotations

import threading
from pathlib import Path

from routing_svc.service.app import load_networks
from routing_svc.service.networks import NetworkRegistry
from routing_svc.service.settings import Settings
from routing_svc.store import EventLog, NetworkRecord
from tests.helpers import DRT


def test_network_registered_by_a_peer_in_between(shared_pg_url: str, tmp_path: Path) -> None:
    settings = Settings(database_url=shared_pg_url, networks={"drt": DRT}, data_dir=tmp_path)
    with EventLog(shared_pg_url) as peer, EventLog(shared_pg_url) as log:
        registry = NetworkRegistry(data_dir=tmp_path, max_bytes=settings.max_network_bytes)
        entry = registry.load("drt", Path(DRT), name="drt")
        real_list = log.list_networks
        calls = [0]

        def list_then_peer_registers() -> list[NetworkRecord]:
            # the peer registers the network right after this instance looked
            calls[0] += 1
            seen = real_list()
            if calls[0] == 1:
                peer.create_network("drt", sha256=entry.network.source_sha256, path=DRT, name="drt")
            return seen

        log.list_networks = list_then_peer_registers  # type: ignore[method-assign]
        load_networks(NetworkRegistry(data_dir=tmp_path, max_bytes=1 << 26), log, settings)
        assert [n.id for n in real_list()] == ["drt"]


def test_two_openers_at_once(shared_pg_url: str, tmp_path: Path) -> None:
    settings = Settings(database_url=shared_pg_url, networks={"drt": DRT}, data_dir=tmp_path)
    barrier = threading.Barrier(2)
    errors: list[BaseException] = []

    def start() -> None:
        with EventLog(shared_pg_url) as log:
            registry = NetworkRegistry(data_dir=tmp_path, max_bytes=settings.max_network_bytes)
            registry.load("drt", Path(DRT), name="drt")
            barrier.wait()
            try:
                load_networks(registry, log, settings)
            except BaseException as exc:  # pragma: no cover - the failure being tested
                errors.append(exc)

    threads = [threading.Thread(target=start) for _ in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert errors == []
