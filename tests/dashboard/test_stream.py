"""``GET /v1/fleets/{id}/stream`` over real sockets, on SQLite and PostgreSQL."""

from __future__ import annotations

import re
import signal
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest

from tests.dashboard.service_client import ServiceClient
from tests.dashboard.sse import Message, messages, take_logs
from tests.helpers import LiveServer

StartServer = Callable[..., LiveServer]
Connect = Callable[[LiveServer], ServiceClient]
TIMEOUT = httpx.Timeout(30.0)


@pytest.fixture
def start_server(db_url: str, tmp_path: Path) -> Iterator[StartServer]:
    """``start_server(workers=1)``: a server on this test's database (several share it)."""
    servers: list[LiveServer] = []

    def start(*, workers: int = 1) -> LiveServer:
        server = LiveServer(db_url, tmp_path, workers=workers).start()
        servers.append(server)
        return server

    yield start
    for server in servers:
        server.stop()


def positions(api: ServiceClient, count: int) -> list[dict[str, object]]:
    return [{"edge": e.id, "offset": e.length / 3} for e in api.spread_edges(count)]


def open_stream(http: httpx.Client, url: str, fleet_id: str, **kwargs: object) -> httpx.Response:
    request = http.build_request("GET", f"{url}/v1/fleets/{fleet_id}/stream", **kwargs)  # type: ignore[arg-type]
    return http.send(request, stream=True)


def open_streams(server: LiveServer) -> float:
    text = httpx.get(server.url + "/metrics").text
    match = re.search(r"^routing_svc_sse_streams (\S+)$", text, re.MULTILINE)
    assert match is not None
    return float(match.group(1))


def test_new_events_arrive_in_order_with_their_results(
    start_server: StartServer, connect: Connect
) -> None:
    server = start_server()
    api = connect(server)
    api.create_fleet("f1", ["A", "B", "A"], reference_demand={"kind": "uniform"})
    with httpx.Client(timeout=TIMEOUT) as http:
        response = open_stream(http, server.url, "f1")
        try:
            assert response.status_code == 200
            assert response.headers["content-type"].startswith("text/event-stream")
            assert response.headers["cache-control"] == "no-cache"
            stream = messages(response)
            assert next(stream).retry == 1000
            spots = positions(api, 3)
            posted = [
                api.post_target("f1", spots[0]),
                api.post_target("f1", spots[1], requires=["A", "B"]),
                api.post_target("f1", spots[2], requires=["B"]),
            ]
            logs, others = take_logs(stream, 3)
        finally:
            response.close()
    assert [m.id for m in logs] == [str(r["seq"]) for r in posted] == ["2", "3", "4"]
    for message, result in zip(logs, posted, strict=True):
        body = message.json()
        assert body["seq"] == result["seq"] and body["kind"] == "target"
        assert body["result"] == result
        assert {"served_by", "moved", "new_position", "target", "requires"} <= set(body["result"])
    metrics = [m.json() for m in others if m.event == "metrics"]
    assert metrics and metrics[0]["version"] >= 1 and metrics[0]["optimum"] is not None


def test_a_stream_resumes_after_the_last_event_id(
    start_server: StartServer, connect: Connect
) -> None:
    server = start_server()
    api = connect(server)
    api.create_fleet("f1", ["A", "A"])
    for spot in positions(api, 4):
        api.post_target("f1", spot)  # events 2..5

    def first_logs(count: int, **kwargs: object) -> list[Message]:
        with httpx.Client(timeout=TIMEOUT) as http:
            response = open_stream(http, server.url, "f1", **kwargs)
            try:
                return take_logs(messages(response), count)[0]
            finally:
                response.close()

    assert [m.id for m in first_logs(2, headers={"Last-Event-ID": "3"})] == ["4", "5"]
    assert [m.id for m in first_logs(1, params={"after": 4})] == ["5"]
    both = first_logs(1, params={"after": 1}, headers={"Last-Event-ID": "4"})
    assert [m.id for m in both] == ["5"]
    (created,) = first_logs(1, params={"after": 0})
    assert created.id == "1" and created.json()["kind"] == "fleet_created"


def test_events_written_through_another_server_reach_the_stream(
    start_server: StartServer, connect: Connect
) -> None:
    """Two servers on one database (two hosts), the reader with two workers."""
    writer = start_server()
    reader = start_server(workers=2)
    api = connect(writer)
    api.create_fleet("f1", ["A", "B"])
    with httpx.Client(timeout=TIMEOUT) as http:
        response = open_stream(http, reader.url, "f1")
        try:
            stream = messages(response)
            next(stream)
            posted = [api.post_target("f1", spot) for spot in positions(api, 5)]
            logs, _ = take_logs(stream, 5)
        finally:
            response.close()
    assert [m.json()["result"] for m in logs] == posted


def test_a_deleted_fleet_ends_its_stream(start_server: StartServer, connect: Connect) -> None:
    server = start_server()
    api = connect(server)
    api.create_fleet("f1", ["A"])
    with httpx.Client(timeout=TIMEOUT) as http:
        response = open_stream(http, server.url, "f1")
        try:
            stream = messages(response)
            next(stream)
            assert api.http.delete("/v1/fleets/f1").status_code == 204
            rest = list(stream)  # ends by itself
        finally:
            response.close()
    logs = [m for m in rest if m.event == "log"]
    assert [m.json()["kind"] for m in logs] == ["fleet_deleted"]
    after_delete = httpx.get(server.url + "/v1/fleets/f1/stream")
    assert after_delete.status_code == 404


def test_bad_requests_get_problems(start_server: StartServer, connect: Connect) -> None:
    server = start_server()
    api = connect(server)
    api.create_fleet("f1", ["A"])
    missing = httpx.get(server.url + "/v1/fleets/nope/stream")
    assert missing.status_code == 404
    assert missing.headers["content-type"] == "application/problem+json"
    for bad in [b"x1", "²".encode("latin-1"), b"-3", b"1.5"]:
        r = httpx.get(server.url + "/v1/fleets/f1/stream", headers={b"Last-Event-ID": bad})
        assert r.status_code == 422
        assert "last-event-id" in r.json()["detail"].lower()  # header names are case-blind
    negative = httpx.get(server.url + "/v1/fleets/f1/stream", params={"after": -1})
    assert negative.status_code == 422


def test_a_stream_stops_when_its_client_goes(start_server: StartServer, connect: Connect) -> None:
    server = start_server()
    api = connect(server)
    api.create_fleet("f1", ["A"])
    with httpx.Client(timeout=TIMEOUT) as http:
        response = open_stream(http, server.url, "f1")
        stream = messages(response)  # closing this generator would close the response
        next(stream)
        assert open_streams(server) == 1.0
        response.close()
    give_up = time.monotonic() + 20.0  # a bounded wait for the server to notice, not a timing check
    while open_streams(server) != 0.0 and time.monotonic() < give_up:
        time.sleep(0.05)
    assert open_streams(server) == 0.0


@pytest.mark.parametrize("workers", [1, 2])
def test_sigterm_ends_open_streams_and_the_server_exits(
    start_server: StartServer, connect: Connect, workers: int
) -> None:
    server = start_server(workers=workers)
    api = connect(server)
    api.create_fleet("f1", ["A"])
    with httpx.Client(timeout=TIMEOUT) as http:
        response = open_stream(http, server.url, "f1")
        try:
            stream = messages(response)
            next(stream)
            # waits for the exit; LiveServer gives up after 30 s, well before the
            # stream's own lifetime (60 s) would have ended it
            server.kill(signal.SIGTERM)
            rest = list(stream)  # the stream ended cleanly (no truncated chunk)
        finally:
            response.close()
    assert server.process is not None
    assert server.process.returncode in (0, -signal.SIGTERM)
    assert all(m.event in ("metrics", "log") for m in rest)
