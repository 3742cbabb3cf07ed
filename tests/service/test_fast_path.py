"""The ASGI fast path of ``POST .../targets`` answers exactly like FastAPI's route.

Two apps on two fresh databases, one with the fast path and one without, get
the same requests in the same order: valid targets, idempotent retries and
every kind of bad input. Every answer must be the same status, content type
and bytes, and the fast path must have answered the valid ones itself.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient

from tests.helpers import NET, edge, fast_answers, fleet_body

Request = tuple[str, bytes, list[tuple[str, str]]]


def _target(e: int, offset: float | None = None, **extra: object) -> bytes:
    where = float(NET.length[e]) / 2 if offset is None else offset
    return json.dumps({"position": {"edge": edge(e), "offset": where}, **extra}).encode()


def _requests() -> list[Request]:
    rng = np.random.default_rng(7)
    valid = [_target(int(e)) for e in rng.integers(NET.n_edges, size=12)]
    out: list[Request] = [("/v1/fleets/f1/targets", body, []) for body in valid]
    path = "/v1/fleets/f1/targets"
    keyed = [("Idempotency-Key", "k-1")]
    out += [
        (path, _target(5), keyed),
        (path, _target(5), keyed),  # retry: the stored answer
        (path, _target(6), keyed),  # same key, other body: conflict
        (path, b"{", []),  # malformed JSON
        (path, b'{"position": {"edge": "' + edge(3).encode() + b'", "offset": NaN}}', []),
        (path, b'{"position": {"edge": "no-such-edge", "offset": 0.0}}', []),
        (path, _target(9, offset=float(NET.length[9]) + 50.0), []),  # off the edge
        (path, _target(9, requires=["no-such-type"]), []),
        (path, _target(9, requires=["default", "default", "default", "default"]), []),
        (path, _target(9), [("Idempotency-Key", "")]),
        (path, _target(9), [("Idempotency-Key", "x" * 201)]),
        (path, _target(9), [("Idempotency-Key", "a"), ("Idempotency-Key", "b")]),
        (path, b'{"position": {"x": 1.0e12, "y": 0.0}}', []),
        (path, b"[]", []),
        ("/v1/fleets/nobody/targets", _target(9), []),
        (path, _target(11), [("Idempotency-Key", "k-2")]),
        (path, _target(12), []),
    ]
    return out


def _answers(client: TestClient, requests: list[Request]) -> list[tuple[int, str, bytes]]:
    assert client.post("/v1/fleets", json=fleet_body()).status_code == 201
    answers = []
    for path, body, headers in requests:
        sent = [("content-type", "application/json"), *headers]
        r = client.post(path, content=body, headers=sent)
        answers.append((r.status_code, r.headers["content-type"], r.content))
    return answers


def test_fast_path_answers_like_the_route(
    make_client: Callable[..., TestClient], tmp_path: Path
) -> None:
    requests = _requests()
    before = fast_answers()
    fast = _answers(make_client(f"sqlite:///{tmp_path / 'fast.db'}"), requests)
    served_fast = fast_answers() - before
    route = _answers(
        make_client(f"sqlite:///{tmp_path / 'route.db'}", target_fast_path=False), requests
    )
    assert fast_answers() - before == served_fast  # the route app never used it
    for i, (a, b) in enumerate(zip(fast, route, strict=True)):
        assert a == b, (i, requests[i], a, b)
    statuses = [status for status, _, _ in fast]
    assert statuses.count(200) == 12 + 2 + 3  # a repeated key header: the route takes one
    assert {409, 404, 422} <= set(statuses)
    # valid targets, the keyed retry and the errors the writer reports are answered by
    # the fast path; everything else falls through to the route
    assert served_fast >= 16
    seqs = [json.loads(body)["seq"] for status, _, body in fast if status == 200]
    assert seqs == [*range(2, 15), 14, 15, 16, 17]
