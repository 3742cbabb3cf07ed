"""The OpenAPI contract, fuzzed with every schemathesis check against a live server.

A real ``routing-svc serve`` (uvicorn on a socket) with one fleet; schemathesis
reads its ``/openapi.json`` and the repository's ``schemathesis.toml`` (the
rules JSON Schema cannot state), then

- each operation with generated requests, valid and invalid (``parametrize``:
  examples, coverage - undeclared methods included - and fuzzing), and
- sequences of operations linked by the ids they return (the state machine),

and every response must pass **all** checks: no server error, declared status,
content type, headers and body schema, invalid requests rejected, valid ones
accepted, ``Allow`` on 405, deleted resources gone, ...

Seeded (``ROUTING_SVC_FUZZ_SEED``, default :data:`DEFAULT_SEED`); the number of
examples is bounded for CI and scales with ``ROUTING_SVC_SOAK_SCALE``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, seed, settings
from schemathesis.config import SchemathesisConfig
from schemathesis.schemas import BaseSchema

from tests.helpers import LiveServer, fleet_body, scaled

DEFAULT_SEED = 20261125
SEED = int(os.environ.get("ROUTING_SVC_FUZZ_SEED", str(DEFAULT_SEED)))
REPO = Path(__file__).resolve().parents[2]
EXAMPLES = scaled(25)
"""Generated requests per operation and phase (and state machine runs)."""

FUZZ_SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=list(HealthCheck),
    database=None,
)


@pytest.fixture(scope="module")
def live_api(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A live server on its own SQLite file, with one fleet (``f1``) to find."""
    tmp = tmp_path_factory.mktemp("fuzzing")
    server = LiveServer(f"sqlite:///{tmp / 'events.db'}", tmp)
    try:
        server.start()
        httpx.post(server.url + "/v1/fleets", json=fleet_body(), timeout=60).raise_for_status()
        yield server
    finally:
        server.stop()


@pytest.fixture(scope="module")
def api_schema(live_api: LiveServer) -> BaseSchema:
    """The live server's OpenAPI document with the project's schemathesis configuration."""
    config = SchemathesisConfig.from_path(str(REPO / "schemathesis.toml"))
    config.update(seed=SEED, max_failures=None)
    return schemathesis.openapi.from_url(live_api.url + "/openapi.json", config=config)


schema = schemathesis.pytest.from_fixture("api_schema")


@schema.parametrize()
@seed(SEED)
@FUZZ_SETTINGS
def test_every_operation_keeps_the_contract(case: schemathesis.Case[Any]) -> None:
    case.call_and_validate(timeout=30)


def test_linked_operations_keep_the_contract(api_schema: BaseSchema) -> None:
    """Create, read, serve, delete ... in generated orders, along the links schemathesis
    infers from the ids the answers carry (``use_after_free`` and
    ``ensure_resource_availability`` among the checks)."""
    machine = seed(SEED)(api_schema.as_state_machine())
    machine.run(
        settings=settings(
            max_examples=EXAMPLES,
            deadline=None,
            suppress_health_check=list(HealthCheck),
            database=None,
            stateful_step_count=6,
        )
    )
