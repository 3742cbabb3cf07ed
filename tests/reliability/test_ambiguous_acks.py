"""Issue 6, item 2: acknowledgements lost on the way back.

A loopback TCP proxy (asyncio, in this test) sits between the client and a live
server. It forwards every request; then, by connection number, it either resets
the client connection once the server has answered (the answer is lost), holds
the answer past the client's timeout, or passes it on. The client retries with
the same ``Idempotency-Key`` until it gets an answer: every target is applied
exactly once and every retry gets byte-identical bytes.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import socket
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx

from routing_svc.store import EventLog
from tests.helpers import LiveServer, fleet_body, record_figures, replay, scaled, target_stream

CLIENT_TIMEOUT_S = 0.5
HOLD_S = 0.8  # longer than the client timeout


class FaultyProxy:
    """Forward to ``upstream``; connection ``i`` is reset / delayed / passed by ``i % 3``."""

    def __init__(self, upstream_port: int) -> None:
        self.upstream_port = upstream_port
        self.counter = itertools.count()
        self.counts = {"reset": 0, "delayed": 0, "passed": 0}
        self.loop = asyncio.new_event_loop()
        self.ready = threading.Event()
        self.port = 0
        self.handlers: set[asyncio.Task[None]] = set()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)

    def __enter__(self) -> FaultyProxy:
        self.thread.start()
        self.server = asyncio.run_coroutine_threadsafe(self._listen(), self.loop).result(10)
        return self

    def __exit__(self, *_: object) -> None:
        asyncio.run_coroutine_threadsafe(self._shutdown(), self.loop).result(10)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()

    async def _listen(self) -> asyncio.Server:
        server = await asyncio.start_server(self._handle, "127.0.0.1", 0)
        self.port = server.sockets[0].getsockname()[1]
        return server

    async def _shutdown(self) -> None:
        self.server.close()
        await self.server.wait_closed()
        for task in self.handlers:
            task.cancel()
        await asyncio.gather(*self.handlers, return_exceptions=True)
        await asyncio.sleep(0.05)  # let the aborted transports finish closing

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self.handlers.add(task)
        mode = ("reset", "delayed", "passed")[next(self.counter) % 3]
        self.counts[mode] += 1
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.upstream_port)

        async def pump_requests() -> None:
            with contextlib.suppress(ConnectionError, OSError):
                while data := await reader.read(65536):
                    up_writer.write(data)
                    await up_writer.drain()

        pump = asyncio.create_task(pump_requests())
        try:
            while data := await up_reader.read(65536):
                if mode == "reset":  # the server answered: drop the answer with a RST
                    sock = writer.get_extra_info("socket")
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                    break
                if mode == "delayed":
                    await asyncio.sleep(HOLD_S)
                writer.write(data)
                await writer.drain()
        except (ConnectionError, OSError):
            pass
        finally:
            pump.cancel()
            await asyncio.gather(pump, return_exceptions=True)
            writer.transport.abort()
            up_writer.transport.abort()
            self.handlers.discard(task)


def test_lost_and_late_acks_apply_once_with_identical_answers(
    server: Callable[..., LiveServer], sqlite_url: str, tmp_path: Path
) -> None:
    live = server()
    httpx.post(live.url + "/v1/fleets", json=fleet_body()).raise_for_status()
    stream = target_stream(2, scaled(15))
    answers: dict[str, bytes] = {}
    attempts = 0
    started = time.monotonic()
    with FaultyProxy(live.port) as proxy:
        # one connection per request, so that every request meets the proxy's faults
        limits = httpx.Limits(max_keepalive_connections=0)
        with httpx.Client(
            base_url=f"http://127.0.0.1:{proxy.port}", timeout=CLIENT_TIMEOUT_S, limits=limits
        ) as http:
            for i, body in enumerate(stream):
                key = f"amb-{i}"
                while key not in answers:
                    attempts += 1
                    try:
                        r = http.post(
                            "/v1/fleets/f1/targets", json=body, headers={"Idempotency-Key": key}
                        )
                    except httpx.TransportError:
                        continue  # reset or timed out: ambiguous, retry with the same key
                    assert r.status_code == 200, r.text
                    answers[key] = r.content
        counts = dict(proxy.counts)
    assert counts["reset"] >= len(stream) and counts["delayed"] >= len(stream)
    with httpx.Client(base_url=live.url, timeout=30) as http:
        for i, body in enumerate(stream):  # and once more, straight to the server
            key = f"amb-{i}"
            r = http.post("/v1/fleets/f1/targets", json=body, headers={"Idempotency-Key": key})
            assert r.status_code == 200 and r.content == answers[key]
        fleet = http.get("/v1/fleets/f1").json()
    assert fleet["version"] == 1 + len(stream)
    with EventLog(sqlite_url) as log:
        events = log.events_since("f1", 0)[1:]
    assert [e.idempotency_key for e in events] == [f"amb-{i}" for i in range(len(stream))]
    for e in events:
        assert e.result_json is not None
        assert e.result_json.encode() == answers[str(e.idempotency_key)]
    replay(sqlite_url, tmp_path)
    record_figures(
        "ambiguous_acks",
        {
            "targets": len(stream),
            "attempts": attempts,
            "connections": counts,
            "applied": len(events),
            "byte_identical_retries": len(stream),
            "elapsed_s": round(time.monotonic() - started, 1),
        },
        tmp_path,
    )
