"""Shared pieces of the reliability suite: scale, live servers, RSS, figures.

Everything is sized for CI (the whole folder in a few minutes on two shared
cores); ``ROUTING_SVC_SOAK_SCALE`` (default 1) multiplies counts and durations
for local soaks. The figures each test measured are printed at the end of the
run (``pytest_terminal_summary``), with or without ``-s``, and written as JSON.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import FIGURES, SCALE, LiveServer


def pytest_terminal_summary(terminalreporter: Any) -> None:
    if FIGURES:
        terminalreporter.section(f"reliability figures (ROUTING_SVC_SOAK_SCALE={SCALE})")
        for name, figures in FIGURES:
            terminalreporter.write_line(f"{name}: {json.dumps(figures)}")


@pytest.fixture
def sqlite_url(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'events.db'}"


@pytest.fixture
def server(sqlite_url: str, tmp_path: Path) -> Iterator[Callable[..., LiveServer]]:
    """``server(workers=1, extra=())`` starts a live server on this test's SQLite file."""
    started: list[LiveServer] = []

    def start(*, workers: int = 1, extra: tuple[str, ...] = ()) -> LiveServer:
        s = LiveServer(sqlite_url, tmp_path, workers=workers, extra=extra).start()
        started.append(s)
        return s

    yield start
    for s in started:
        s.stop()
