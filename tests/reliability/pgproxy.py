"""A loopback TCP proxy (asyncio, on a thread of the test) in front of a real server.

Three states, switched at any time:

- ``forward``: bytes pass both ways;
- ``partition``: connections stay open and new ones are accepted, but nothing is
  forwarded in either direction (what a client sees when packets vanish behind a
  proxy or load balancer that keeps answering TCP);
- ``down``: the listener is closed and every connection is reset (a stopped server).

Leaving ``partition`` or ``down`` for ``forward`` resets the connections that lost
bytes, as the peers of a long partition would find.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
import threading


class TcpProxy:
    """Forward ``127.0.0.1:<port>`` to ``upstream_host:upstream_port``."""

    def __init__(self, upstream_host: str, upstream_port: int) -> None:
        self.upstream = (upstream_host, upstream_port)
        self.state = "forward"
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.port = 0
        self.server: asyncio.Server | None = None
        self.links: set[tuple[asyncio.StreamWriter, asyncio.StreamWriter]] = set()

    def __enter__(self) -> TcpProxy:
        self.thread.start()
        self._run(self._listen())
        return self

    def __exit__(self, *_: object) -> None:
        self._run(self._close(listen_again=False))
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()

    def forward(self) -> None:
        """Heal: reset what lost bytes, forward again (listening again if down)."""
        was = self.state
        self.state = "forward"
        if was == "partition":
            self._run(self._reset_links())
        elif was == "down":
            self._run(self._listen())

    def partition(self) -> None:
        """Stop forwarding; keep every connection open."""
        self.state = "partition"

    def down(self) -> None:
        """Close the listener and reset every connection."""
        self.state = "down"
        self._run(self._close(listen_again=False))

    def _run(self, coroutine: object) -> None:
        asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(10)  # type: ignore[arg-type]

    async def _listen(self) -> None:
        self.server = await asyncio.start_server(self._handle, "127.0.0.1", self.port)
        self.port = self.server.sockets[0].getsockname()[1]

    async def _close(self, *, listen_again: bool) -> None:
        if self.server is not None:
            self.server.close()
            self.server = None
        await self._reset_links()
        if listen_again:
            await self._listen()

    async def _reset_links(self) -> None:
        for client, upstream in list(self.links):
            for writer in (client, upstream):
                sock = writer.get_extra_info("socket")
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                writer.transport.abort()
        self.links.clear()
        await asyncio.sleep(0.01)

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self.state == "partition":  # accepted, never answered
            link: tuple[asyncio.StreamWriter, asyncio.StreamWriter] = (writer, writer)
            self.links.add(link)
            with contextlib.suppress(ConnectionError, OSError):
                while await reader.read(65536):
                    pass
            return
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.upstream)
        except OSError:
            writer.transport.abort()
            return
        link = (writer, up_writer)
        self.links.add(link)

        async def pump(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
            with contextlib.suppress(ConnectionError, OSError):
                while data := await src.read(65536):
                    if self.state != "forward":
                        continue  # the bytes vanish
                    dst.write(data)
                    await dst.drain()
            with contextlib.suppress(ConnectionError, OSError):
                dst.transport.abort()

        await asyncio.gather(pump(reader, up_writer), pump(up_reader, writer))
        self.links.discard(link)
