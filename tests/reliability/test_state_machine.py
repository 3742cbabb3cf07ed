"""Issue 6, item 5 (second half): a Hypothesis state machine against a simple model.

Rules create fleets, post targets (fresh or retried idempotency keys), restart the
application on the same SQLite file and replay the log; after every step the
service must agree with a model that only counts versions and remembers which
key got which answer.
"""

from __future__ import annotations

from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any

from fastapi.testclient import TestClient
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import Bundle, RuleBasedStateMachine, initialize, invariant, rule

from routing_svc.network import load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.service.app import create_app
from routing_svc.service.settings import Settings

DRT = resolve_network("drt")
EDGES = load_network(DRT).edge_ids


class ServiceMachine(RuleBasedStateMachine):
    fleets = Bundle("fleets")

    def __init__(self) -> None:
        super().__init__()
        self.tmp = TemporaryDirectory()
        self.settings = Settings(
            database_url=f"sqlite:///{Path(self.tmp.name) / 'm.db'}",
            networks={"drt": str(DRT)},
            data_dir=Path(self.tmp.name) / "networks",
        )
        self.client = self._open()
        self.versions: dict[str, int] = {}
        self.answers: dict[tuple[str, str], tuple[dict[str, Any], bytes]] = {}

    def _open(self) -> TestClient:
        client = TestClient(create_app(self.settings))
        client.__enter__()
        return client

    @initialize()
    def start(self) -> None:
        assert self.client.get("/healthz").status_code == 200

    @rule(target=fleets, name=st.sampled_from(["a", "b", "c"]), n=st.integers(1, 4))
    def create_fleet(self, name: str, n: int) -> str:
        body = {
            "id": name,
            "network": "drt",
            "vehicles": [{"id": f"v{i}", "position": {"edge": EDGES[i * 50]}} for i in range(n)],
        }
        r = self.client.post("/v1/fleets", json=body)
        if name in self.versions:
            assert r.status_code == 409
        else:
            assert r.status_code == 201, r.text
            self.versions[name] = 1
        return name

    @rule(
        fleet=fleets,
        edge=st.integers(0, len(EDGES) - 1),
        key=st.sampled_from(["k1", "k2", "k3", None]),
    )
    def post_target(self, fleet: str, edge: int, key: str | None) -> None:
        body = {"position": {"edge": EDGES[edge], "offset": 0.0}}
        headers = {"Idempotency-Key": key} if key else {}
        r = self.client.post(f"/v1/fleets/{fleet}/targets", json=body, headers=headers)
        known = self.answers.get((fleet, key)) if key else None
        if known is None:
            assert r.status_code == 200, r.text
            self.versions[fleet] += 1
            assert r.json()["seq"] == self.versions[fleet]
            if key:
                self.answers[(fleet, key)] = (body, r.content)
        elif known[0] == body:
            assert r.status_code == 200 and r.content == known[1]
        else:
            assert r.status_code == 409

    @rule()
    def restart(self) -> None:
        self.client.__exit__(None, None, None)
        self.client = self._open()

    @rule(fleet=fleets)
    def replay_matches(self, fleet: str) -> None:
        report = self.client.app.state.fleets.verify(fleet)  # type: ignore[attr-defined]
        assert report["version"] == self.versions[fleet]
        assert report["snapshot_identical"] in (True, None)

    @invariant()
    def versions_agree(self) -> None:
        for fleet, version in self.versions.items():
            assert self.client.get(f"/v1/fleets/{fleet}").json()["version"] == version

    def teardown(self) -> None:
        self.client.__exit__(None, None, None)
        self.tmp.cleanup()


ServiceMachine.TestCase.settings = settings(
    max_examples=15,
    stateful_step_count=12,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
TestServiceMachine = ServiceMachine.TestCase
