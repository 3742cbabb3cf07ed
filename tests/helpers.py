"""Plain helpers shared by test modules of several packages.

Fixtures live in the conftest of the package that uses them; what is here is
plain functions and constants, imported as ``from tests.helpers import ...``.

- The DRT network of the service tests, settings and live servers (``LiveServer``).
- The reliability suite's scale, figures, replay and integrity checks.
- Fleet bodies and seeded target streams.
- Routes, metrics and event loops of the service.
- What a client sees from a failing store (reliability tests).
- Appends and event-log groups (store tests).
- The nearest-vehicle search against networkx (network tests).
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from prometheus_client import REGISTRY

from routing_svc.demand.network import hotspot_mixture
from routing_svc.errors import RoutingSvcError
from routing_svc.network import RoadSpace, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.sa.space import Assignment, Requirement
from routing_svc.service import replay_command
from routing_svc.service.settings import Settings
from routing_svc.store import (
    BuildGroup,
    EventLog,
    EventRecord,
    FleetGroup,
    GroupItem,
    NewEvent,
    Snapshot,
)
from routing_svc.types import NetPosition
from tests.network.conftest import NetCase

# --- the DRT network of the service tests, live servers, the reliability suite -------

DRT = str(resolve_network("drt"))


def make_settings(db_url: str, tmp_path: Path, **extra: object) -> Settings:
    return Settings(
        database_url=db_url,
        networks={"drt": DRT},
        data_dir=tmp_path / "networks",
        **extra,  # type: ignore[arg-type]
    )


BENCH = Path(__file__).resolve().parents[1] / "bench"


def run_bench(script: str, cwd: Path, *options: str) -> subprocess.CompletedProcess[str]:
    """``python bench/<script> options`` run from ``cwd``, its output captured."""
    return subprocess.run(
        [sys.executable, str(BENCH / script), *options],
        capture_output=True, text=True, timeout=600, cwd=cwd,
    )  # fmt: skip


def bench_report(script: str, cwd: Path, *options: str) -> tuple[dict[str, Any], str]:
    """:func:`run_bench`, which must succeed: the JSON document it printed, and its
    standard error."""
    done = run_bench(script, cwd, *options)
    assert done.returncode == 0, done.stderr
    report: dict[str, Any] = json.loads(done.stdout)
    return report, done.stderr


def assert_bench_refuses(script: str, cwd: Path, cases: Sequence[tuple[list[str], str]]) -> None:
    """Each ``(options, message)`` of ``cases`` makes ``bench/<script>`` exit 2 with
    ``message`` in the last line of its standard error, before printing any result."""
    for options, message in cases:
        done = run_bench(script, cwd, *options)
        assert done.returncode == 2, (options, done.stderr)
        assert message in done.stderr.strip().splitlines()[-1]
        assert done.stdout == ""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


class LiveServer:
    """``routing-svc serve`` in a subprocess (real uvicorn, real sockets); it keeps its port
    across restarts, and ``extra`` options go to ``serve``."""

    def __init__(
        self, db_url: str, tmp_path: Path, *, workers: int = 1, extra: tuple[str, ...] = ()
    ) -> None:
        self.db_url = db_url
        self.tmp_path = tmp_path
        self.workers = workers
        self.extra = extra
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.process: subprocess.Popen[bytes] | None = None
        self.log = tmp_path / f"server-{self.port}.log"

    def start(self) -> LiveServer:
        env = {**os.environ, "DATABASE_URL": self.db_url}
        cmd = [
            sys.executable, "-m", "routing_svc.cli", "serve",
            "--port", str(self.port), "--net", f"drt={DRT}", "--no-demo",
            "--workers", str(self.workers), "--data-dir", str(self.tmp_path / "networks"),
            "--log-level", "warning", *self.extra,
        ]  # fmt: skip
        with self.log.open("ab") as out:
            self.process = subprocess.Popen(
                cmd, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
            )
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"server exited: {self.log.read_text()[-2000:]}")
            try:
                if httpx.get(self.url + "/healthz", timeout=1.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.05)
        raise RuntimeError(f"server did not start: {self.log.read_text()[-2000:]}")

    def kill(self, sig: int = signal.SIGKILL) -> None:
        assert self.process is not None
        os.killpg(self.process.pid, sig)
        self.process.wait(timeout=60)

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.kill(signal.SIGTERM)


SCALE = float(os.environ.get("ROUTING_SVC_SOAK_SCALE", "1"))
FIGURES: list[tuple[str, dict[str, Any]]] = []


def scaled(value: float) -> int:
    """``value`` times ``ROUTING_SVC_SOAK_SCALE``, at least 1."""
    return max(1, round(value * SCALE))


def record_figures(name: str, figures: dict[str, Any], directory: Path) -> None:
    """Keep ``figures`` for the end-of-run summary and write them to ``directory``."""
    FIGURES.append((name, figures))
    (directory / f"{name}.json").write_text(json.dumps(figures, indent=2))
    print(f"{name}: {json.dumps(figures)}")


def vm_kib(pid: int, field: str) -> int:
    """A ``/proc/PID/status`` field in KiB (``VmRSS``, ``VmHWM``)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise LookupError(field)


def replay(db_url: str, tmp_path: Path) -> dict[str, Any]:
    """``routing-svc replay --database-url URL``: must exit 0; its JSON report."""
    out = subprocess.run(
        [sys.executable, "-m", "routing_svc.cli", "replay", "--database-url", db_url,
         "--data-dir", str(tmp_path / "networks")],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    report: dict[str, Any] = json.loads(out.stdout)
    assert report["ok"] is True
    return report


def integrity(db_url: str) -> list[str]:
    """``EventLog.integrity_check()`` (SQLite ``integrity_check`` and seq gaps)."""
    with EventLog(db_url) as log:
        return log.integrity_check()


def serial_replay(db_url: str, tmp_path: Path, fleet_id: str) -> dict[str, Any]:
    """The fleet as ``GET /v1/fleets/{id}`` shows it, rebuilt from its whole log, in order."""
    from routing_svc.service.app import load_networks
    from routing_svc.service.networks import NetworkRegistry
    from routing_svc.service.runtime import FleetRuntime
    from routing_svc.service.settings import Settings

    settings = Settings(database_url=db_url, data_dir=tmp_path / "networks")
    with EventLog(db_url) as log:
        registry = NetworkRegistry(data_dir=settings.data_dir, max_bytes=settings.max_network_bytes)
        load_networks(registry, log, settings)
        events = log.events_since(fleet_id, 0)
        entry = registry.get(log.get_fleet(fleet_id).network_id)
    runtime = FleetRuntime(
        fleet_id, entry, json.loads(events[0].payload_json), recent_window=settings.recent_window
    )
    for e in events[1:]:
        runtime.replay(e.seq, e.kind, e.payload_json, e.result_json)
    described: dict[str, Any] = json.loads(json.dumps(runtime.describe()))
    return described


# --- fleets and targets on DRT ----------------------------------------------------------

NET = load_network(DRT)


def edge(i: int) -> str:
    """The id of the DRT network's edge number ``i``."""
    return NET.edge_ids[i]


def fleet_body(fleet_id: str = "f1", **extra: Any) -> dict[str, Any]:
    """A ``POST /v1/fleets`` body: three vehicles on DRT, plus ``extra`` fields."""
    body: dict[str, Any] = {
        "id": fleet_id,
        "network": "drt",
        "vehicles": [
            {"id": "v1", "position": {"edge": edge(0), "offset": 1.0}},
            {"id": "v2", "position": {"edge": edge(100), "offset": 0.0}},
            {"id": "v3", "position": {"edge": edge(300), "offset": 2.5}},
        ],
    }
    body.update(extra)
    return body


def targets(seed: int, n: int) -> list[dict[str, Any]]:
    """``n`` target bodies at the start of random DRT edges."""
    rng = np.random.default_rng(seed)
    return [
        {"position": {"edge": edge(int(e)), "offset": 0.0}}
        for e in rng.integers(NET.n_edges, size=n)
    ]


def target_stream(seed: int, n: int) -> list[dict[str, Any]]:
    """``n`` target bodies on random DRT edges, at random offsets along them."""
    rng = np.random.default_rng(seed)
    out = []
    for e in rng.integers(NET.n_edges, size=n):
        offset = float(rng.uniform(0.0, float(NET.length[int(e)])))
        out.append({"position": {"edge": edge(int(e)), "offset": offset}})
    return out


def spread_fleet_body(fleet_id: str, **extra: Any) -> dict[str, Any]:
    """A ``POST /v1/fleets`` body: four vehicles spread over DRT, plus ``extra`` fields."""
    body: dict[str, Any] = {
        "id": fleet_id,
        "network": "drt",
        "vehicles": [
            {"id": f"v{i}", "position": {"edge": edge(e), "offset": 0.0}}
            for i, e in enumerate((0, 100, 300, 500))
        ],
    }
    body.update(extra)
    return body


def hotspot_stream(n: int) -> list[dict[str, Any]]:
    """``n`` target bodies drawn from one three-hotspot demand on DRT (the same every call)."""
    demand = hotspot_mixture(NET, centres=3, rng=np.random.default_rng(21))
    return [
        {"position": {"edge": edge(z.edge), "offset": z.offset}}
        for z in demand.sample(np.random.default_rng(22), n)
    ]


def post_batches(
    client: Any, fleet_id: str, targets: list[dict[str, Any]], chunk: int = 50
) -> list[Any]:
    """Post ``targets`` through ``targets:batch``, ``chunk`` a request; every result."""
    results: list[Any] = []
    for start in range(0, len(targets), chunk):
        r = client.post(
            f"/v1/fleets/{fleet_id}/targets:batch", json={"targets": targets[start : start + chunk]}
        )
        assert r.status_code == 200, r.text
        results.extend(r.json()["results"])
    return results


def replay_report(db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> Any:
    """``routing-svc replay`` of ``db_url`` in process: exit 0, and its JSON report."""
    args = argparse.Namespace(
        db=None, database_url=db_url, fleet=[], data_dir=tmp_path / "networks"
    )
    capsys.readouterr()
    code = replay_command.run(args)
    report = json.loads(capsys.readouterr().out)
    assert code == 0, report
    return report


def replay_ok(db_url: str, tmp_path: Any) -> dict[str, Any]:
    """``routing-svc replay`` of ``db_url``: exit 0, and its JSON report."""
    out = subprocess.run(
        [sys.executable, "-m", "routing_svc.cli", "replay", "--database-url", db_url,
         "--data-dir", str(tmp_path / "networks")],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    report: dict[str, Any] = json.loads(out.stdout)
    return report


# --- the service: routes, metrics, event loops ------------------------------------------


def every_route(routes: Any) -> list[tuple[str, str]]:
    """(method, path) of every route, looking inside included routers."""
    out: list[tuple[str, str]] = []
    for route in routes:
        inner = getattr(route, "original_router", None)
        if inner is not None:
            out += every_route(inner.routes)
        else:
            out += [(m, route.path) for m in getattr(route, "methods", None) or ()]
    return out


def fast_answers() -> float:
    """Targets answered by the ASGI fast path so far (a process-wide counter)."""
    value = REGISTRY.get_sample_value("routing_svc_target_fast_path_total")
    return 0.0 if value is None else value


def handoff_timeouts() -> float:
    """Commits whose thread had not started within the loop's bounded hand-over."""
    value = REGISTRY.get_sample_value("routing_svc_commit_handoff_timeouts_total")
    assert value is not None
    return value


def blocked_until(release: threading.Event) -> Callable[[], None]:
    """A commit that waits until ``release`` is set."""

    def commit() -> None:
        release.wait()

    return commit


def run(coroutine: Any) -> Any:
    """Run ``coroutine`` on a fresh loop in a thread of its own (a test's thread may
    have a loop running already); fail on anything the loop's exception handler saw."""

    def on_a_fresh_loop() -> Any:
        loop = asyncio.new_event_loop()
        seen: list[dict[str, Any]] = []
        loop.set_exception_handler(lambda _, context: seen.append(context))
        try:
            result = loop.run_until_complete(coroutine)
        finally:
            loop.close()
        assert seen == []
        return result

    with ThreadPoolExecutor(1) as thread:
        return thread.submit(on_a_fresh_loop).result(timeout=120)


# --- a failing store, as a client sees it -----------------------------------------------

STORE_TYPES = {
    "urn:routing-svc:problem:storage-unavailable",
    "urn:routing-svc:problem:storage-timeout",
    "urn:routing-svc:problem:commit-outcome-unknown",
}
LEAKS = ("sqlalche.me", "psycopg", "sqlite3", "pysqlite", "OperationalError", "Traceback")


def shows_secret(text: str, secrets: Sequence[str]) -> str | None:
    """The first of ``secrets`` that ``text`` holds as a whole token (a port inside a longer
    number does not count), or None."""
    for secret in secrets:
        if re.search(rf"(?<![0-9A-Za-z]){re.escape(secret)}(?![0-9A-Za-z])", text):
            return secret
    return None


def check_store_problem(r: httpx.Response, secrets: tuple[str, ...], log: Path) -> str:
    """A 503 from the store: problem+json, stable type, Retry-After, error id in the
    server's log, nothing internal in the answer. Returns its type."""
    assert r.status_code == 503, r.text
    assert r.headers["content-type"] == "application/problem+json"
    assert int(r.headers["retry-after"]) >= 1
    body = r.json()
    assert body["type"] in STORE_TYPES, body
    assert len(body["detail"]) < 120 and body["error_id"]
    # The random error id and the date may hold a port's digits by chance: leave them out,
    # and look for a secret as a whole token.
    shown = {k: v for k, v in body.items() if k != "error_id"}
    answer = json.dumps(shown) + "".join(
        f"{k}: {v}\n" for k, v in r.headers.items() if k.lower() != "date"
    )
    for leak in LEAKS:
        assert leak not in answer, (leak, answer)
    assert not shows_secret(answer, secrets), answer
    deadline = time.monotonic() + 5
    while body["error_id"] not in log.read_text(errors="replace"):
        assert time.monotonic() < deadline, "the error id is not in the server's log"
        time.sleep(0.05)
    return str(body["type"])


def wait_health(url: str, status: int, within_s: float = 20) -> tuple[dict[str, Any], float]:
    """Poll ``/healthz`` until it answers ``status``; its body and the seconds it took."""
    started = time.monotonic()
    while True:
        r = httpx.get(url + "/healthz", timeout=10)
        if r.status_code == status:
            if status == 503:
                assert int(r.headers["retry-after"]) >= 1 and r.json()["reason"]
            return r.json(), time.monotonic() - started
        assert time.monotonic() - started < within_s, r.text
        time.sleep(0.1)


def settle_keys(
    http: httpx.Client, fleet: str, keyed: dict[str, dict[str, Any]], acked: dict[str, bytes]
) -> None:
    """Post every key (again) until each has an answer; acknowledged ones must not change."""
    for key, body in keyed.items():
        for _ in range(50):
            r = http.post(
                f"/v1/fleets/{fleet}/targets", json=body, headers={"Idempotency-Key": key}
            )
            if r.status_code == 200:
                break
            time.sleep(0.2)
        assert r.status_code == 200, r.text
        assert acked.setdefault(key, r.content) == r.content


def check_log(db_url: str, fleet: str, acked: dict[str, bytes]) -> int:
    """Every acknowledged key is stored once, with the answer its client got."""
    with EventLog(db_url) as log:
        stored = log.events_since(fleet, 0)[1:]
    keys = [e.idempotency_key for e in stored]
    assert len(keys) == len(set(keys)) == len(acked)
    for e in stored:
        assert e.result_json is not None
        assert e.result_json.encode() == acked[str(e.idempotency_key)]
    return len(stored)


# --- appends and event-log groups -------------------------------------------------------


def append_group(
    log: EventLog,
    fleet_id: str,
    *,
    expected_version: int,
    requests: Sequence[tuple[str | None, str | None]],
    build: BuildGroup,
    snapshot: Snapshot | None = None,
) -> list[GroupItem]:
    """One fleet's group appended in a transaction of its own (:meth:`EventLog.append_groups`,
    the service's own path); one item per request."""
    group = FleetGroup(fleet_id, expected_version, tuple(requests), build, snapshot)
    (items,) = log.append_groups([group])
    return items


def append_one(
    log: EventLog,
    fleet_id: str,
    *,
    expected_version: int,
    build: Callable[[list[EventRecord]], Sequence[NewEvent]],
    idempotency_key: str | None = None,
    request_hash: str | None = None,
    snapshot: Snapshot | None = None,
) -> GroupItem:
    """One request appended as a group of one: ``build(missed) -> events``; its item, or
    its error (an idempotency key used for another request) raised."""
    (item,) = append_group(
        log,
        fleet_id,
        expected_version=expected_version,
        requests=[(idempotency_key, request_hash)],
        build=lambda missed, fresh: [build(missed)],
        snapshot=snapshot,
    )
    if item.error is not None:
        raise item.error
    return item


def target_event(n: int) -> NewEvent:
    """A target event numbered ``n`` (payload and result name it)."""
    return NewEvent("target", f'{{"n": {n}}}', f'{{"moved": {n}}}')


def one_each(missed: list[EventRecord], fresh: list[int]) -> list[list[NewEvent] | RoutingSvcError]:
    """A group's build: one target event per fresh version."""
    return [[target_event(i)] for i in fresh]


# --- the nearest-vehicle search against networkx ----------------------------------------

RTOL = 1e-9


def reference_times(
    case: NetCase,
    costs: Mapping[str, float],
    weighted: object,
    target: NetPosition,
    positions: list[NetPosition],
    speeds: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Each vehicle's cost and time to ``target`` according to networkx."""
    ref = case.reference
    start = ref.start_costs(case.ids(target), costs, weighted)
    cost = np.array(
        [ref.vehicle_cost(case.ids(p), case.ids(target), costs, start) for p in positions]
    )
    return cost, cost / speeds


def check_assignment(
    case: NetCase,
    space: RoadSpace,
    result: Assignment[NetPosition],
    target: NetPosition,
    positions: list[NetPosition],
    requirement: Requirement,
    ref_cost: np.ndarray,
    ref_time: np.ndarray,
) -> None:
    """Served vehicles, times, mover and route agree with the reference costs."""
    groups, counts = requirement.vehicle_groups, requirement.counts
    served = list(result.served_by)
    slot = 0
    for g, k in enumerate(counts.tolist()):
        ours = served[slot : slot + k]
        members = np.flatnonzero(groups == g).tolist()
        expected = sorted(members, key=lambda i: (ref_time[i], i))[:k]
        our_times = np.array(result.times[slot : slot + k])
        np.testing.assert_allclose(our_times, ref_time[expected], rtol=RTOL)
        np.testing.assert_allclose(our_times, ref_time[ours], rtol=RTOL)
        candidates = np.sort(ref_time[members])
        gaps = np.diff(candidates[: k + 1]) if len(candidates) > k else np.diff(candidates)
        if (gaps > RTOL * np.maximum(candidates[1 : len(gaps) + 1], 1.0)).all():
            assert ours == expected
        slot += k
    times = np.array(result.times)
    last = max(range(len(served)), key=lambda j: (times[j], -served[j]))
    assert result.mover == served[last]
    assert result.completion_time == times[last]
    np.testing.assert_allclose(result.mover_cost, ref_cost[result.mover], rtol=RTOL)
    check_route(case, space, result, positions[result.mover], target)


def check_route(
    case: NetCase,
    space: RoadSpace,
    result: Assignment[NetPosition],
    position: NetPosition,
    target: NetPosition,
) -> None:
    """The route is a connected edge path from the mover to the target that costs mover_cost."""
    route = result.route
    assert isinstance(route, np.ndarray)
    assert route[0] == position.edge and route[-1] == target.edge
    ids = [case.network.edge_ids[e] for e in route]
    assert all(case.reference.graph.has_edge(a, b) for a, b in itertools.pairwise(ids))
    rate, cost = space.edge_costs.rate, space.edge_costs.cost
    if len(route) == 1:
        walked = (target.offset - position.offset) * rate[target.edge]
    else:
        walked = (
            (case.network.length[position.edge] - position.offset) * rate[position.edge]
            + cost[route[1:-1]].sum()
            + target.offset * rate[target.edge]
        )
    np.testing.assert_allclose(walked, result.mover_cost, rtol=RTOL, atol=1e-9)


def run_queries(
    case: NetCase,
    space: RoadSpace,
    rng: np.random.Generator,
    *,
    n_targets: int,
    positions: list[NetPosition],
    speeds: np.ndarray,
    requirement: Requirement,
    costs: Mapping[str, float],
) -> None:
    """Random targets: every assignment of ``space`` agrees with networkx."""
    weighted = case.reference.weighted(costs)
    for target in case.random_positions(rng, n_targets):
        result = space.assign(target, positions, speeds, requirement)
        ref_cost, ref_time = reference_times(case, costs, weighted, target, positions, speeds)
        check_assignment(case, space, result, target, positions, requirement, ref_cost, ref_time)
