"""``routing-svc serve`` refuses a PostgreSQL connection that could lose acknowledged events."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import psycopg
import pytest

from routing_svc.cli import build_parser
from routing_svc.service.command import settings_env
from tests.conftest import libpq_conninfo
from tests.helpers import DRT, LiveServer, free_port

MESSAGE = (
    "routing-svc serve: storage error: refusing to use a PostgreSQL server that can lose "
    "committed events (synchronous_commit=off)"
)


def serve(url: str, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "DATABASE_URL": url}
    cmd = [
        sys.executable, "-m", "routing_svc.cli", "serve", "--port", str(free_port()),
        "--net", f"drt={DRT}", "--no-demo", "--data-dir", str(tmp_path / "networks"),
    ]  # fmt: skip
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)


def test_serve_refuses_synchronous_commit_off(
    pg_url_with: Callable[[str], str], pg_database: str, pg_schema: str, tmp_path: Path
) -> None:
    url = pg_url_with("-c synchronous_commit=off")
    out = serve(url, tmp_path)
    assert out.returncode != 0
    assert MESSAGE in out.stderr, out.stderr
    # one clear line, not a traceback from the application's lifespan
    assert "Traceback" not in out.stdout + out.stderr
    assert "turn these settings on" in out.stderr
    # refused before anything was written: the schema holds no tables
    with psycopg.connect(libpq_conninfo(pg_database)) as conn:
        tables = conn.execute(
            "SELECT count(*) FROM information_schema.tables WHERE table_schema = %s",
            (pg_schema,),
        ).fetchone()
    assert tables == (0,)


def test_serve_accepts_the_same_schema_with_durable_settings(
    pg_url_with: Callable[[str], str], tmp_path: Path
) -> None:
    # control: the same schema and command line with durable settings starts and is healthy
    server = LiveServer(pg_url_with("-c synchronous_commit=on"), tmp_path).start()
    server.stop()


def test_sqlite_stays_the_default(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DATABASE_URL", raising=False)
    monkeypatch.chdir(tmp_path)
    args = build_parser("serve").parse_args(["serve", "--no-demo"])
    url = settings_env(args)["DATABASE_URL"]
    assert url == f"sqlite:///{(tmp_path / 'var' / 'routing_svc.db').resolve()}"
    monkeypatch.setenv("DATABASE_URL", "postgresql+psycopg://u@h/db")
    assert settings_env(args)["DATABASE_URL"] == "postgresql+psycopg://u@h/db"
