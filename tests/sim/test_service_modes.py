"""Live travel times, a running service over HTTP, the tracking experiment."""

from __future__ import annotations

import gzip
import math
from dataclasses import replace
from pathlib import Path

import httpx

from routing_svc.sim import CosimResult, CosimSpec, parse_policies, run_cosim
from routing_svc.sim.plots import write_figures
from tests.sim.conftest import serve_fleets


def test_traffic_costs_push_sumo_travel_times(small_spec: CosimSpec, tmp_path: Path) -> None:
    spec = replace(small_spec, policies=parse_policies("sa"), traffic_period=60.0)
    result = run_cosim(spec, out_dir=tmp_path, progress=False)
    (run,) = result.runs
    assert run.traffic_updates >= int(spec.end // 60.0)
    assert run.served >= run.requests - 1


def test_a_running_service_over_http_gives_the_in_process_result(
    persons_result: CosimResult, small_spec: CosimSpec, fleet_server: str, tmp_path: Path
) -> None:
    spec = replace(small_spec, policies=parse_policies("sa"), service_url=fleet_server)
    (remote,) = run_cosim(spec, out_dir=tmp_path, progress=False).runs
    (local,) = persons_result.by_policy()["sa"]
    assert remote.waits == local.waits
    assert remote.snapshots == local.snapshots


def test_tracking_moving_hotspots(small_spec: CosimSpec, tmp_path: Path) -> None:
    spec = replace(small_spec, policies=parse_policies("sa,sa-floor"), shift_at=450.0)
    result = run_cosim(spec, out_dir=tmp_path, progress=False)
    levels = sorted({round(v, 9) for _, v in result.optimum_curve[3]})
    assert len(levels) == 2  # one optimum per demand phase
    for name in ("sa", "sa-floor"):
        curve = result.curves[(name, 3)]
        assert all(math.isfinite(v) for _, v in curve)
    figures = write_figures(result, out_dir=tmp_path / "figures", prefix="tracking")
    assert set(figures) == {"waits", "positions", "objective"}
    assert all(p.stat().st_size > 1000 for p in figures.values())


def test_cosim_over_http_with_the_service_started_on_the_same_gzipped_network(
    grid_net: Path, small_spec: CosimSpec, tmp_path: Path
) -> None:
    net = tmp_path / "grid.net.xml.gz"  # the cosim adds it as "grid", the name it was started with
    net.write_bytes(gzip.compress(grid_net.read_bytes()))
    with serve_fleets({"grid": net}, tmp_path) as url:
        spec = replace(
            small_spec,
            network=str(net),
            policies=parse_policies("sa"),
            service_url=url,
            duration=300.0,
            warmup=60.0,
            drain=240.0,
            history=20,
        )
        (run,) = run_cosim(spec, out_dir=tmp_path / "out", progress=False).runs
        networks = httpx.get(url + "/v1/networks").json()["items"]
    assert run.requests >= 1 and run.served >= run.requests - 1
    assert [n["id"] for n in networks] == ["grid"]
