"""Persons asking for taxi rides, every policy, real SUMO: served, measured by SUMO."""

from __future__ import annotations

import json
import math
from pathlib import Path

from defusedxml import ElementTree

from routing_svc.sim import CosimResult

SERVICE_POLICIES = ("sa", "sa-available", "sa-cold", "static", "optimum")
SUMO_POLICIES = ("sumo-stop", "sumo-closest", "sumo-circling", "sumo-taxistand")


def _sumo_waits(tripinfo: Path) -> dict[str, tuple[float, str]]:
    """Each person's ride ``waitingTime`` and vehicle, read straight from SUMO's file."""
    root = ElementTree.parse(tripinfo).getroot()
    waits = {}
    for person in root.iter("personinfo"):
        ride = person.find("ride")
        assert ride is not None
        waits[person.get("id")] = (float(ride.get("waitingTime")), ride.get("vehicle"))
    return waits


def test_every_policy_serves_the_requests(persons_result: CosimResult) -> None:
    runs = persons_result.by_policy()
    assert set(runs) == {*SERVICE_POLICIES, *SUMO_POLICIES}
    for name, (run,) in runs.items():
        assert run.requests >= 8, name
        assert run.served >= run.requests - 1, name  # at most the last one still waiting
        assert math.isfinite(run.mean_wait) and run.mean_wait > 0.0, name
        assert run.failed == 0, name
        assert run.empty_km > 0.0 and run.driven_km >= run.empty_km, name


def test_every_policy_sees_the_same_requests(persons_result: CosimResult) -> None:
    requested = {run.policy: [t for t, _, _ in run.waits] for run in persons_result.runs}
    first = next(iter(requested.values()))
    assert all(times == first for times in requested.values())


def test_waits_are_sumos_personinfo(persons_result: CosimResult) -> None:
    for run in persons_result.runs:
        from_file = _sumo_waits(Path(run.tripinfo))
        assert sorted(w for w, _ in from_file.values()) == sorted(w for _, w, _ in run.waits)
        served = [w for w, vehicle in from_file.values() if vehicle != "NULL"]
        assert math.isclose(run.mean_wait, sum(served) / len(served), rel_tol=1e-12)
        fleet = {vehicle for _, vehicle in from_file.values() if vehicle != "NULL"}
        assert fleet and all(v.startswith("fleet") for v in fleet)


def test_service_policies_send_the_vehicle_the_service_dispatched(
    persons_result: CosimResult,
) -> None:
    for name in SERVICE_POLICIES:
        (run,) = persons_result.by_policy()[name]
        assert len(run.predicted) == len(run.waits)
        assert run.fallbacks == 0 and not any(other for _, other in run.predicted), name
        served = [t for (t, _), (_, _, ok) in zip(run.predicted, run.waits, strict=True) if ok]
        assert all(math.isfinite(t) and t >= 0.0 for t in served), name
        assert run.state_batches > 0, name


def test_service_levels_and_load_of_every_policy(persons_result: CosimResult) -> None:
    for name, (run,) in persons_result.by_policy().items():
        summary = run.summary()
        assert summary["p50_wait_s"] <= summary["p90_wait_s"] <= summary["p95_wait_s"], name
        within = list(summary["within"].values())
        assert list(summary["within"]) == ["300", "600", "900"]
        assert within == sorted(within) and 0.0 <= within[0] <= within[-1] <= 1.0, name
        assert 0.0 < summary["busy_fraction"] < 1.0, name
        assert summary["requests_per_vehicle_hour"] == run.requests / (4 * 900.0 / 3600.0)


def test_sa_moves_reference_positions_and_frozen_policies_do_not(
    persons_result: CosimResult,
) -> None:
    runs = persons_result.by_policy()
    for name in ("static", "optimum"):
        (run,) = runs[name]
        assert run.snapshots[0][1] == run.snapshots[-1][1], name
    (cold,) = runs["sa-cold"]
    assert cold.snapshots[0][1] != cold.snapshots[-1][1]
    (static,) = runs["static"]
    assert cold.snapshots[0][1] == static.snapshots[0][1]  # same start
    (optimum,) = runs["optimum"]
    best = persons_result.optimum[3]
    assert best is not None
    assert len(optimum.snapshots[0][1]) == len(best.positions) == 4


def _inserted(fleet_file: Path) -> dict[str, str]:
    """Each fleet vehicle's insertion edge, read from the route file SUMO loaded."""
    root = ElementTree.parse(fleet_file).getroot()
    edges = {}
    for vehicle in root.iter("vehicle"):
        route = vehicle.find("route")
        assert route is not None
        edges[vehicle.get("id")] = route.get("edges")
    return edges


def test_sumo_vehicles_start_at_the_fleets_first_references(
    persons_result: CosimResult,
) -> None:
    runs = persons_result.by_policy()
    (sa,) = runs["sa"]
    (cold,) = runs["sa-cold"]
    # sa starts at the p-median of its history, sa-cold at the common start positions
    assert sa.snapshots[0][1] != cold.snapshots[0][1]
    for name in SERVICE_POLICIES:
        (run,) = runs[name]
        fleet_file = Path(run.tripinfo).parent / f"fleet-{name}.rou.xml"
        first = {vehicle: edge for vehicle, (edge, _) in run.snapshots[0][1].items()}
        assert _inserted(fleet_file) == first, name


def test_objective_curves_against_the_optimum(persons_result: CosimResult) -> None:
    best = persons_result.optimum[3]
    assert best is not None and best.expected_cost > 0.0
    optimum_curve = persons_result.curves[("optimum", 3)]
    assert all(math.isclose(v, best.expected_cost, rel_tol=1e-9) for _, v in optimum_curve)
    for name in ("sa", "sa-cold", "static"):
        curve = persons_result.curves[(name, 3)]
        assert all(v >= best.expected_cost * (1 - 1e-9) for _, v in curve), name
    assert "sumo-stop" not in {p for p, _ in persons_result.curves}


def test_summary_json_is_written(persons_result: CosimResult, tmp_path: Path) -> None:
    prepared = persons_result.prepared
    assert prepared is not None
    out = prepared.seeds[0].workdir.parent
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["policies"]) == set(persons_result.by_policy())
    sa = summary["policies"]["sa"]
    for key in ("mean_wait_s", "p90_wait_s", "within", "busy_fraction", "empty_km", "sim_speed"):
        assert key in sa
    assert summary["spec"]["mode"] == "persons"
