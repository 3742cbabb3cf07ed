"""Incidents at the places of background vehicles: served, measured by SUMO."""

from __future__ import annotations

import math

import pytest
from defusedxml import ElementTree

from routing_svc.sim import CosimResult
from routing_svc.sim.scenario import empirical_demand, expected_wait


def test_incidents_are_served_by_every_policy(incidents_result: CosimResult) -> None:
    runs = incidents_result.by_policy()
    assert set(runs) == {"sa", "static", "optimum", "sumo-stop", "sumo-circling"}
    for name, (run,) in runs.items():
        assert run.requests >= 8, name
        assert run.served >= run.requests - 1, name
        assert math.isfinite(run.mean_wait) and run.mean_wait > 0.0, name


def test_incidents_happen_where_background_vehicles_drive(incidents_result: CosimResult) -> None:
    prepared = incidents_result.prepared
    assert prepared is not None
    (seed,) = prepared.seeds
    assert seed.requests and len(seed.history) > 10
    background = ElementTree.parse(seed.workdir / "tripinfo-background.xml").getroot()
    trips = [t for t in background.iter("tripinfo") if t.get("id", "").startswith("bg")]
    assert trips, "the background-only run recorded no trips"
    lengths = dict(zip(prepared.network.edge_ids, prepared.network.length, strict=True))
    for request in seed.requests:
        assert request.edge in lengths
        assert 0.0 <= request.offset <= lengths[request.edge] + 1e-6
    times = [r.time for r in seed.requests]
    assert times == sorted(times)
    assert incidents_result.spec.warmup <= times[0] and times[-1] < 120.0 + 900.0


def test_optimum_is_the_p_median_of_incidents_recorded_apart(
    incidents_result: CosimResult,
) -> None:
    prepared = incidents_result.prepared
    assert prepared is not None
    (seed,) = prepared.seeds
    sample = seed.demand_sample
    assert abs(len(sample) - incidents_result.spec.incident_sample) <= 0.5 * len(sample)
    assert len(sample) > 3 * len(seed.requests)
    best = incidents_result.optimum[3]
    assert best is not None and len(best.positions) == 4
    on_sample = expected_wait(
        prepared.space, best.positions, empirical_demand(prepared.network, sample)
    )
    assert on_sample == pytest.approx(best.expected_cost, rel=1e-9)
    (static,) = incidents_result.by_policy()["static"]
    static_value = incidents_result.curves[("static", 3)][0][1]
    assert best.expected_cost <= static_value + 1e-9
    assert static.snapshots
