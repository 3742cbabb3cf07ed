"""HTTP throughput of ``POST /v1/fleets/{id}/targets`` against a trivial FastAPI endpoint.

Both are served by uvicorn (1 worker, same options) and loaded by the same
generator (``wrk``, Debian package ``wrk``) with the same concurrency, in the
same run; the ratio of the two is the figure that counts (absolute numbers on
these machines drift 2x between runs). Both servers are up at once and the
two loads take turns (``--rounds``, 5 by default: trivial, service, trivial,
...), so that the machine's drift during the run hits both alike.

The service runs with SQLite (WAL, ``synchronous=FULL``) and a 50-vehicle fleet
on the BadHersfeld network; with ``--postgres URL`` it also runs against
PostgreSQL with 1 and 2 service instances (each its own port, wrk spreading
the load over both), and measures the cost of one ``EventLog.append``
transaction in-process on both backends (one writer on one fleet, four writers
on four fleets, four writers on one fleet), the figure the scaling plan in
``docs/scaling.md`` rests on. Fleet ids carry a per-run suffix, so the same
database can be reused.

Usage::

    python bench/http_throughput.py [--seconds 10] [--connections 16] [--rounds 5] [--probe F]
                         [--postgres URL] [--quick]

The same service with the single-target fast path off (``ROUTING_SVC_TARGET_FAST_PATH=false``)
is loaded the same way in the same run, each against the trivial app in turns;
``fast_path_gain`` is the ratio of the two services' ratios to the trivial app (the
head-to-head that decides whether the fast path stays).

And the same service again with every consolidation solved inside the target that made
it due (``ROUTING_SVC_CONSOLIDATION_WORKERS=0``) instead of in a worker process:
``background_consolidation_gain`` (single targets, each against the trivial app in
turns; the batch route; the single-target p99, inline over background).

The fleets use the service's defaults; ``--probe 0`` measures the paper's rule alone.

Prints one JSON document.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from bench_shared import SHARED

ROOT = Path(__file__).resolve().parent.parent
RUN = uuid.uuid4().hex[:6]  # suffix of this run's fleet ids
BADHERSFELD = SHARED / "badhersfeld.net.xml.gz"

TRIVIAL_APP = """
from fastapi import FastAPI
from pydantic import BaseModel

class Position(BaseModel):
    edge: str
    offset: float = 0.0

class Target(BaseModel):
    position: Position
    requires: list[str] | None = None

app = FastAPI()

@app.post("/v1/fleets/{fleet_id}/targets")
async def post_target(fleet_id: str, target: Target) -> dict:
    return {"fleet": fleet_id, "edge": target.position.edge, "seq": 1}
"""

WRK_SCRIPT = """
local bodies = {%s}
local paths = {%s}
local n = 0
request = function()
  n = n + 1
  local body = bodies[(n %% #bodies) + 1]
  local path = paths[(n %% #paths) + 1]
  return wrk.format("POST", path, {["Content-Type"] = "application/json"}, body)
end
done = function(summary, latency, requests)
  io.write(string.format("RESULT %%d %%d %%d %%d %%d %%d %%d %%d\\n", summary.requests,
    summary.errors.status + summary.errors.connect + summary.errors.read + summary.errors.write
    + summary.errors.timeout, summary.duration, latency:percentile(50), latency:percentile(99),
    latency.mean, summary.errors.status, summary.errors.timeout))
end
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def wait_up(url: str, proc: subprocess.Popen[bytes]) -> None:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError("server exited during start-up")
        try:
            httpx.get(url, timeout=1.0)
            return
        except httpx.HTTPError:
            time.sleep(0.1)
    raise RuntimeError("server did not start")


def start(cmd: list[str], env: dict[str, str], probe: str) -> subprocess.Popen[bytes]:
    proc = subprocess.Popen(
        cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    wait_up(probe, proc)
    return proc


def stop(proc: subprocess.Popen[bytes]) -> None:
    os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def run_wrk(
    urls: list[str], paths: list[str], bodies: list[str], *, seconds: int, connections: int
) -> dict[str, float]:
    """Run wrk against one or more servers (connections split evenly); sum the results."""
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "load.lua"
        lua_bodies = ",".join("[[" + b + "]]" for b in bodies)
        lua_paths = ",".join('"' + p + '"' for p in paths)
        script.write_text(WRK_SCRIPT % (lua_bodies, lua_paths))
        per = max(1, connections // len(urls))
        procs = [
            subprocess.Popen(
                ["wrk", "-t1", f"-c{per}", f"-d{seconds}s", "--latency", "-s", str(script), url],
                stdout=subprocess.PIPE,
                text=True,
            )
            for url in urls
        ]
        outs = [p.communicate()[0] for p in procs]
    total = errors = status_errors = timeouts = 0
    duration = 0.0
    p50: list[float] = []
    p99: list[float] = []
    for out in outs:
        m = re.search(r"RESULT (\d+) (\d+) (\d+) (\d+) (\d+) (\d+) (\d+) (\d+)", out)
        if m is None:
            raise RuntimeError(f"wrk failed: {out}")
        total += int(m.group(1))
        errors += int(m.group(2))
        status_errors += int(m.group(7))
        timeouts += int(m.group(8))
        duration = max(duration, int(m.group(3)) / 1e6)
        p50.append(int(m.group(4)) / 1000)
        p99.append(int(m.group(5)) / 1000)
    return {
        "requests": total,
        "errors": errors,
        "non_2xx": status_errors,  # answers other than 2xx/3xx (wrk: errors.status)
        "timeouts": timeouts,  # no answer within wrk's 2 s timeout (not counted as requests)
        "requests_per_second": total / duration,
        "p50_ms": max(p50),
        "p99_ms": max(p99),
    }


def merge_rounds(rounds: list[dict[str, float]]) -> dict[str, Any]:
    """Sum alternating wrk rounds into one result (p50: median of the rounds, p99: worst)."""
    total = sum(r["requests"] for r in rounds)
    seconds = sum(r["requests"] / r["requests_per_second"] for r in rounds if r["requests"])
    return {
        "requests": total,
        "errors": sum(r["errors"] for r in rounds),
        "non_2xx": sum(r["non_2xx"] for r in rounds),
        "timeouts": sum(r["timeouts"] for r in rounds),
        "requests_per_second": total / seconds if seconds else 0.0,
        "p50_ms": float(np.median([r["p50_ms"] for r in rounds])),
        "p99_ms": max(r["p99_ms"] for r in rounds),
        "rounds_requests_per_second": [round(r["requests_per_second"], 1) for r in rounds],
    }


def target_bodies(edge_ids: list[str], n: int, seed: int) -> list[str]:
    rng = np.random.default_rng(seed)
    return [
        json.dumps({"position": {"edge": edge_ids[int(i)], "offset": 0.0}})
        for i in rng.integers(len(edge_ids), size=n)
    ]


def create_fleet(
    base: str, edge_ids: list[str], fleet_id: str, vehicles: int, probe: float | None = None
) -> None:
    rng = np.random.default_rng(5)
    body: dict[str, Any] = {
        "id": fleet_id,
        "network": "town",
        "vehicles": [
            {"id": f"v{i:02d}", "position": {"edge": edge_ids[int(e)], "offset": 0.0}}
            for i, e in enumerate(rng.choice(len(edge_ids), size=vehicles, replace=False))
        ],
    }
    if probe is not None:
        body["probe"] = probe
    httpx.post(base + "/v1/fleets", json=body, timeout=60).raise_for_status()


def serve_cmd(port: int, net: Path, data_dir: Path) -> list[str]:
    return [
        sys.executable, "-m", "routing_svc.cli", "serve", "--port", str(port),
        "--net", f"town={net}", "--no-demo", "--workers", "1", "--log-level", "warning",
        "--data-dir", str(data_dir),
    ]  # fmt: skip


def bench_service(
    *, env: dict[str, str], net: Path, tmp: Path, instances: int, edge_ids: list[str],
    seconds: int, connections: int, label: str, baseline: str | None = None, rounds: int = 1,
    probe: float | None = None,
) -> dict[str, Any]:  # fmt: skip
    """Load ``POST .../targets`` (then the batch route) of ``instances`` servers.

    With ``baseline`` (the URL of the trivial app), the single-target load and
    the same load on the baseline take turns in ``rounds`` rounds of
    ``seconds / rounds`` each, so that a change of the machine's speed during
    the run hits both alike; the result then has a ``"baseline"`` entry.
    """
    ports = [free_port() for _ in range(instances)]
    procs = [
        start(serve_cmd(p, net, tmp / "networks"), env, f"http://127.0.0.1:{p}/healthz")
        for p in ports
    ]
    try:
        base = f"http://127.0.0.1:{ports[0]}"
        fleets = [f"{label}{RUN}_{i}" for i in range(4)]
        for fid in fleets:
            create_fleet(base, edge_ids, fid, 50, probe)
        bodies = target_bodies(edge_ids, 500, 1)
        urls = [f"http://127.0.0.1:{p}" for p in ports]
        share = max(1, seconds // rounds)
        ours: list[dict[str, float]] = []
        theirs: list[dict[str, float]] = []
        for _ in range(rounds):
            if baseline is not None:
                load = run_wrk(
                    [baseline], ["/v1/fleets/x/targets"], bodies,
                    seconds=share, connections=connections,
                )  # fmt: skip
                theirs.append(load)
            load = run_wrk(
                urls, [f"/v1/fleets/{f}/targets" for f in fleets], bodies,
                seconds=share, connections=connections,
            )  # fmt: skip
            ours.append(load)
        single = merge_rounds(ours)
        batch_bodies = [
            json.dumps({"targets": [json.loads(b) for b in bodies[i : i + 50]]})
            for i in range(0, 500, 50)
        ]
        batch = run_wrk(
            urls, [f"/v1/fleets/{f}/targets:batch" for f in fleets], batch_bodies,
            seconds=max(2, seconds // 2), connections=max(2, connections // 4),
        )  # fmt: skip
        single["targets_per_second"] = single["requests_per_second"]
        batch["targets_per_second"] = batch["requests_per_second"] * 50
        report = {
            "instances": instances,
            "targets": single,
            "batch": batch,
            "targets_per_second_per_instance": single["targets_per_second"] / instances,
        }
        if theirs:
            report["baseline"] = merge_rounds(theirs)
        return report
    finally:
        for proc in procs:
            stop(proc)


def _append_loop(log: Any, fid: str, n: int, build: Any, sink: list[float]) -> None:
    """``n`` appends to ``fid``, one request a group; the wall time of each goes to ``sink``."""
    from routing_svc.store import FleetGroup

    version = 1  # the writer's cache: it gets the events it missed, as a worker does
    for _ in range(n):
        t0 = time.perf_counter()
        ((item,),) = log.append_groups([FleetGroup(fid, version, ((None, None),), build)])
        version = item.version
        sink.append(time.perf_counter() - t0)


PAYLOAD = json.dumps({"requires": None, "target": {"edge": "e" * 9, "offset": 0.0}})
RESULT = json.dumps({"pad": "x" * 480})  # a target event's result is ~500 bytes


def bench_store(url: str, *, appends: int) -> dict[str, Any]:
    """Wall time of ``EventLog.append_groups`` (one ~570-byte event per transaction), in-process.

    ``serial``: one writer, one fleet. ``four_fleets``: four threads, one fleet
    each (independent row locks; PostgreSQL commits them in parallel, sharing WAL
    flushes), ``sixteen_fleets`` likewise. ``one_fleet``: four threads on the same fleet
    (they queue on its row lock; on SQLite every case queues on the file lock).
    """
    from routing_svc.store import EventLog, NewEvent

    def build(_missed: Any, fresh: list[int]) -> list[Any]:
        return [[NewEvent("target", PAYLOAD, RESULT)]]

    out: dict[str, Any] = {}
    with EventLog(url) as log:
        net = f"bench_{RUN}"
        log.create_network(net, sha256="0" * 64, path="/dev/null", name=net)
        cases = (
            ("serial", 1, 1),
            ("four_fleets", 4, 4),
            ("sixteen_fleets", 16, 16),
            ("one_fleet", 4, 1),
        )
        for name, threads, fleets in cases:
            ids = [f"{net}_{name}_{i}" for i in range(fleets)]
            for fid in ids:
                log.create_fleet(fid, net, "{}", "{}")
            per_thread = appends // threads
            sinks: list[list[float]] = [[] for _ in range(threads)]
            workers = [
                threading.Thread(
                    target=_append_loop, args=(log, ids[i % fleets], per_thread, build, sinks[i])
                )
                for i in range(threads)
            ]
            t0 = time.perf_counter()
            for w in workers:
                w.start()
            for w in workers:
                w.join()
            wall = time.perf_counter() - t0
            lat = [x for sink in sinks for x in sink]
            ms = np.array(lat) * 1000
            out[name] = {
                "threads": threads,
                "fleets": fleets,
                "appends": len(lat),
                "appends_per_second": len(lat) / wall,
                "mean_ms": float(ms.mean()),
                "p50_ms": float(np.percentile(ms, 50)),
                "p99_ms": float(np.percentile(ms, 99)),
            }
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=int, default=10)
    parser.add_argument("--connections", type=int, default=16)
    parser.add_argument(
        "--rounds", type=int, default=5,
        help="the baseline and the service take turns this many times (default 5)",
    )  # fmt: skip
    parser.add_argument("--net", type=Path, default=BADHERSFELD)
    parser.add_argument("--postgres", default=None, help="SQLAlchemy URL of an empty database")
    parser.add_argument("--quick", action="store_true", help="2-second runs")
    parser.add_argument(
        "--probe", type=float, default=None,
        help="the fleets' probe window (fraction of R; default: the service's, 0: off)",
    )  # fmt: skip
    args = parser.parse_args()
    if shutil.which("wrk") is None:
        print("bench/http_throughput.py needs wrk: apt-get install wrk", file=sys.stderr)
        return 2
    if not args.net.is_file():
        print(f"network {args.net} not found", file=sys.stderr)
        return 2
    seconds = 2 if args.quick else args.seconds
    from routing_svc.network import load_network

    edge_ids = list(load_network(args.net).edge_ids)
    report: dict[str, Any] = {
        "benchmark": "POST /v1/fleets/{id}/targets",
        "baseline": "trivial FastAPI POST endpoint with a pydantic body (same uvicorn, same wrk)",
        "network": args.net.name,
        "vehicles_per_fleet": 50,
        "fleet_probe": "service default" if args.probe is None else args.probe,
        "connections": args.connections,
        "seconds": seconds,
    }
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        (tmp / "trivial_app.py").write_text(TRIVIAL_APP)
        port = free_port()
        env = {**os.environ, "PYTHONPATH": str(tmp)}
        trivial = start(
            [sys.executable, "-m", "uvicorn", "trivial_app:app", "--port", str(port),
             "--log-level", "warning", "--workers", "1"],
            env, f"http://127.0.0.1:{port}/docs",
        )  # fmt: skip
        try:
            sqlite_env = {**os.environ, "DATABASE_URL": f"sqlite:///{tmp / 'bench.db'}"}
            report["sqlite"] = bench_service(
                env=sqlite_env, net=args.net, tmp=tmp, instances=1, edge_ids=edge_ids,
                seconds=seconds, connections=args.connections, label="s",
                baseline=f"http://127.0.0.1:{port}", rounds=args.rounds, probe=args.probe,
            )  # fmt: skip
            # head to head, each against the trivial app in turns: the same service with
            # the single-target fast path off, and solving each consolidation inside the
            # target that made it due (no worker process)
            for key, label, setting in (
                ("sqlite_without_fast_path", "r", {"ROUTING_SVC_TARGET_FAST_PATH": "false"}),
                ("sqlite_consolidating_inline", "i", {"ROUTING_SVC_CONSOLIDATION_WORKERS": "0"}),
            ):
                variant_env = {
                    **os.environ,
                    "DATABASE_URL": f"sqlite:///{tmp / f'bench_{label}.db'}",
                    **setting,
                }
                report[key] = bench_service(
                    env=variant_env, net=args.net, tmp=tmp, instances=1, edge_ids=edge_ids,
                    seconds=seconds, connections=args.connections, label=label,
                    baseline=f"http://127.0.0.1:{port}", rounds=args.rounds, probe=args.probe,
                )  # fmt: skip
        finally:
            stop(trivial)
        inline_trivial = report["sqlite_consolidating_inline"].pop("baseline")
        ours, inline = report["sqlite"], report["sqlite_consolidating_inline"]
        report["background_consolidation_gain"] = {
            "single_targets_per_second": (
                ours["targets"]["requests_per_second"]
                / report["sqlite"]["baseline"]["requests_per_second"]
            )
            / (inline["targets"]["requests_per_second"] / inline_trivial["requests_per_second"]),
            "batch_targets_per_second": ours["batch"]["targets_per_second"]
            / inline["batch"]["targets_per_second"],
            "single_p99_ms_inline_over_background": inline["targets"]["p99_ms"]
            / ours["targets"]["p99_ms"],
        }
        report["trivial"] = report["sqlite"].pop("baseline")
        route_trivial = report["sqlite_without_fast_path"].pop("baseline")
        report["fast_path_gain"] = (
            report["sqlite"]["targets"]["requests_per_second"]
            / report["trivial"]["requests_per_second"]
        ) / (
            report["sqlite_without_fast_path"]["targets"]["requests_per_second"]
            / route_trivial["requests_per_second"]
        )
        if args.postgres:
            pg_env = {**os.environ, "DATABASE_URL": args.postgres}
            for n in (1, 2):
                report[f"postgresql_{n}_instances"] = bench_service(
                    env=pg_env, net=args.net, tmp=tmp, instances=n, edge_ids=edge_ids,
                    seconds=seconds, connections=args.connections, label=f"p{n}_",
                    probe=args.probe,
                )  # fmt: skip
        if args.postgres:
            appends = 100 if args.quick else 400
            report["store_append"] = {
                "sqlite": bench_store(f"sqlite:///{tmp / 'store.db'}", appends=appends),
                "postgresql": bench_store(args.postgres, appends=appends),
            }
    trivial_rps = report["trivial"]["requests_per_second"]
    report["ratio_sqlite_vs_trivial"] = (
        report["sqlite"]["targets"]["requests_per_second"] / trivial_rps
    )
    for n in (1, 2):
        key = f"postgresql_{n}_instances"
        if key in report:
            report[f"ratio_{key}_vs_sqlite"] = (
                report[key]["targets"]["requests_per_second"]
                / report["sqlite"]["targets"]["requests_per_second"]
            )
    if "postgresql_1_instances" in report:
        # the PostgreSQL column: targets per second, 1 and 2 instances, next to SQLite's
        report["targets_per_second"] = {
            "sqlite": report["sqlite"]["targets"]["targets_per_second"],
            "postgresql_1_instance": report["postgresql_1_instances"]["targets"][
                "targets_per_second"
            ],
            "postgresql_2_instances": report["postgresql_2_instances"]["targets"][
                "targets_per_second"
            ],
        }
        report["host_cpus"] = os.cpu_count()
    report["target_ratio"] = 0.5
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
