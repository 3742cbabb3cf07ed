"""Issue 6, item 5: schemathesis against the app's own OpenAPI schema, in process (ASGI).

0 server errors and 0 response-schema violations over every operation (the SSE
stream excepted: it never ends), ``max_examples`` bounded for CI.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from schemathesis.checks import not_a_server_error
from schemathesis.core.errors import InvalidSchema
from schemathesis.core.result import Err, Ok
from schemathesis.schemas import APIOperation
from schemathesis.specs.openapi.checks import response_schema_conformance

from routing_svc.service.app import create_app
from tests.reliability.conftest import record_figures, scaled
from tests.reliability.workload import fleet_body
from tests.service.conftest import make_settings


def _operation(
    result: Ok[APIOperation[Any, Any, Any, Any]] | Err[InvalidSchema],
) -> APIOperation[Any, Any, Any, Any]:
    """The operation of a schema entry; a schema error fails the test."""
    if isinstance(result, Err):
        raise AssertionError(f"the OpenAPI document has an invalid operation: {result.err()}")
    return result.ok()


def test_schemathesis_finds_no_server_error(sqlite_url: str, tmp_path: Path) -> None:
    app = create_app(make_settings(sqlite_url, tmp_path))
    calls = 0
    with TestClient(app) as c:
        c.post("/v1/fleets", json=fleet_body()).raise_for_status()
        schema = schemathesis.openapi.from_asgi("/openapi.json", app)
        operations = [_operation(r) for r in schema.get_all_operations()]
        operations = [op for op in operations if not op.path.endswith("/stream")]
        for op in operations:

            @given(case=op.as_strategy())
            @settings(
                max_examples=scaled(30),
                deadline=None,
                suppress_health_check=list(HealthCheck),
                database=None,
            )
            def check(case: schemathesis.Case[Any]) -> None:
                nonlocal calls
                calls += 1
                case.call_and_validate(checks=[not_a_server_error, response_schema_conformance])

            check()
    record_figures(
        "schemathesis",
        {"operations": len(operations), "calls": calls, "server_errors": 0},
        tmp_path,
    )
