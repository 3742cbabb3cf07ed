"""Reading a ``text/event-stream`` response in tests (the parts of the format we use)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import httpx


@dataclass(frozen=True)
class Message:
    """One server-sent message."""

    event: str
    data: str
    id: str | None
    retry: int | None

    def json(self) -> Any:
        return json.loads(self.data)


def messages(response: httpx.Response) -> Iterator[Message]:
    """The messages of a streaming response, as they arrive; ends with the stream."""
    event: str = "message"
    data: list[str] = []
    event_id: str | None = None
    retry: int | None = None
    for line in response.iter_lines():
        if line == "":
            if data or retry is not None:
                yield Message(event, "\n".join(data), event_id, retry)
            event, data, event_id, retry = "message", [], None, None
            continue
        if line.startswith(":"):
            continue
        field, _, value = line.partition(":")
        value = value.removeprefix(" ")
        if field == "event":
            event = value
        elif field == "data":
            data.append(value)
        elif field == "id":
            event_id = value
        elif field == "retry":
            retry = int(value)


def take_logs(stream: Iterator[Message], count: int) -> tuple[list[Message], list[Message]]:
    """Read until ``count`` ``log`` messages came; return them and the other messages."""
    logs: list[Message] = []
    others: list[Message] = []
    for message in stream:
        (logs if message.event == "log" else others).append(message)
        if len(logs) == count:
            break
    return logs, others
