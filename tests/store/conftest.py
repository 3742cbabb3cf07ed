"""Fixtures for the store tests: every store test runs on SQLite and on PostgreSQL.

PostgreSQL: one database per test session (``routing_svc_test_<pid>_<hex>``,
dropped at the end) on the server named by ``ROUTING_SVC_TEST_PG_URL``
(default: the local ``test`` database as ``postgres``), and one schema per
test inside it, selected through the connection's ``search_path``.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import psycopg
import pytest
from sqlalchemy.engine import make_url

PG_ADMIN_URL = os.environ.get(
    "ROUTING_SVC_TEST_PG_URL", "postgresql+psycopg://postgres@127.0.0.1:5432/test"
)


def libpq_conninfo(url: str) -> str:
    """The libpq form of a SQLAlchemy PostgreSQL URL."""
    parsed = make_url(url).set(drivername="postgresql")
    return parsed.render_as_string(hide_password=False)


def pg_url(database_url: str, *, schema: str, options: str = "") -> str:
    """A SQLAlchemy URL for ``database_url`` whose connections use ``schema``."""
    parsed = make_url(database_url)
    pg_options = f"-c search_path={schema} {options}".strip()
    return parsed.update_query_dict({"options": pg_options}).render_as_string(hide_password=False)


@pytest.fixture(scope="session")
def pg_database() -> Iterator[str]:
    """A fresh PostgreSQL database for this test session; dropped afterwards."""
    name = f"routing_svc_test_{os.getpid()}_{uuid.uuid4().hex[:8]}"
    with psycopg.connect(libpq_conninfo(PG_ADMIN_URL), autocommit=True) as admin:
        admin.execute(f'CREATE DATABASE "{name}"')
    try:
        yield make_url(PG_ADMIN_URL).set(database=name).render_as_string(hide_password=False)
    finally:
        with psycopg.connect(libpq_conninfo(PG_ADMIN_URL), autocommit=True) as admin:
            admin.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@pytest.fixture
def pg_schema(pg_database: str) -> Iterator[str]:
    """A fresh schema in the session database; dropped after the test."""
    schema = f"t_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(libpq_conninfo(pg_database), autocommit=True) as conn:
        conn.execute(f"CREATE SCHEMA {schema}")
    try:
        yield schema
    finally:
        with psycopg.connect(libpq_conninfo(pg_database), autocommit=True) as conn:
            conn.execute(f"DROP SCHEMA IF EXISTS {schema} CASCADE")


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """An empty database of each backend: a SQLite file, or a PostgreSQL schema."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'events.db'}"
    database: str = request.getfixturevalue("pg_database")
    schema: str = request.getfixturevalue("pg_schema")
    return pg_url(database, schema=schema)


@pytest.fixture
def pg_url_with(pg_database: str, pg_schema: str) -> object:
    """``pg_url_with(options)``: a URL of this test's schema with extra server options."""

    def build(options: str) -> str:
        return pg_url(pg_database, schema=pg_schema, options=options)

    return build
