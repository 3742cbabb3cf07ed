"""A service that cannot be reached, or goes away part-way through an import: one clear
line, whole chunks, and a re-run that applies each call once."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from routing_svc.errors import ServiceUnreachable
from routing_svc.history import HistoryInterrupted, HttpHistoryClient, read_calls, replay_history
from routing_svc.history.places import place_remotely
from routing_svc.history.replay import CallChunk, ChunkAnswer
from routing_svc.network import CompiledNetwork
from tests.history.conftest import LiveServers, cli, fleet_at, random_calls, write_edge_calls


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port


@pytest.fixture
def silent_server() -> Iterator[str]:
    """A TCP server that accepts connections and never answers; its URL."""
    listener = socket.create_server(("127.0.0.1", 0))
    held: list[socket.socket] = []
    stop = threading.Event()

    def accept() -> None:
        listener.settimeout(0.1)
        while not stop.is_set():
            try:
                held.append(listener.accept()[0])
            except TimeoutError:
                continue

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{listener.getsockname()[1]}"
    stop.set()
    thread.join(timeout=5)
    for conn in held:
        conn.close()
    listener.close()


def test_an_import_against_a_closed_port_exits_2_with_one_line(
    tmp_path: Path, drt: CompiledNetwork
) -> None:
    calls = random_calls(drt, 5, seed=1)
    path = write_edge_calls(tmp_path / "calls.csv", calls)
    url = f"http://127.0.0.1:{_closed_port()}"
    out = cli("history", "import", str(path), "--fleet", "f", "--service-url", url, "--quiet")
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    assert out.stderr.splitlines() == [
        f"routing-svc history: service unreachable: cannot connect for GET {url}/v1/fleets/f: "
        "[Errno 111] Connection refused"
    ]


def test_a_service_that_never_answers_times_out_and_a_write_may_have_been_applied(
    silent_server: str,
) -> None:
    with HttpHistoryClient(silent_server, timeout=0.3) as client:
        with pytest.raises(ServiceUnreachable) as read:
            client.get_fleet("f")
        assert read.value.detail == f"GET {silent_server}/v1/fleets/f: no answer within 0.3 s"
        with pytest.raises(ServiceUnreachable) as write:
            client.post_target("f", {"edge": "e", "offset": 0.0}, idempotency_key="k")
        assert write.value.detail == (
            f"POST {silent_server}/v1/fleets/f/targets: no answer within 0.3 s; "
            "the request may have been applied"
        )
        with pytest.raises(ServiceUnreachable) as query:
            client.assign("f", {"edge": "e", "offset": 0.0})
        assert query.value.detail == (
            f"POST {silent_server}/v1/fleets/f/assign: no answer within 0.3 s"
        )


class _KilledAfter(HttpHistoryClient):
    """Kills the live server with SIGKILL before sending chunk ``after``."""

    def __init__(self, url: str, servers: LiveServers, *, after: int) -> None:
        super().__init__(url)
        self.servers, self.after, self.sent = servers, after, 0

    def post_chunk(self, fleet_id: str, chunk: CallChunk, *, idempotency_key: str) -> ChunkAnswer:
        if self.sent == self.after:
            self.servers.kill()
        self.sent += 1
        return super().post_chunk(fleet_id, chunk, idempotency_key=idempotency_key)


def test_a_service_killed_mid_import_keeps_whole_chunks_and_a_rerun_applies_each_call_once(
    tmp_path: Path, drt: CompiledNetwork, live_server: LiveServers
) -> None:
    calls = random_calls(drt, 50, seed=9)
    path = write_edge_calls(tmp_path / "calls.csv", calls)
    table = read_calls(path)
    url = live_server()
    with HttpHistoryClient(url) as setup:
        setup.create_fleet(fleet_at([(calls[0]["edge"], 0.0), (calls[1]["edge"], 0.0)]))
        placed = place_remotely(table, setup, "f", progress=False)
    with (
        _KilledAfter(url, live_server, after=2) as dying,
        pytest.raises(HistoryInterrupted) as interrupted,
    ):
        replay_history(table, placed, dying, "f", chunk_size=10, progress=False)
    assert interrupted.value.detail.startswith(
        f"chunk 3 of 5 failed (service unreachable: cannot connect for POST {url}/v1/fleets/f/"
    )
    assert interrupted.value.detail.endswith(
        "chunks 1 to 2 are applied, and the same command again applies each call once"
    )
    restarted = live_server()  # the same event log
    with HttpHistoryClient(restarted) as client:
        assert client.get_fleet("f")["version"] == 21
        resumed = replay_history(table, placed, client, "f", chunk_size=10, progress=False)
        assert (resumed.applied, resumed.applied_chunks, resumed.version_after) == (30, 3, 51)
    events = httpx.get(f"{restarted}/v1/fleets/f/events", params={"limit": 100}).json()
    seqs = [e["seq"] for e in events["items"] if e["kind"] == "target"]
    assert seqs == list(range(2, 52))
