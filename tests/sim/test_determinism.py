"""The same seed gives the same result; another seed gives other requests."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from routing_svc.sim import CosimResult, CosimSpec, parse_policies, run_cosim
from routing_svc.sim.measures import PolicyRun


def _outcome(run: PolicyRun) -> tuple[object, ...]:
    """Everything a run measured except wall-clock time."""
    summary = {k: v for k, v in run.summary().items() if k not in ("wall_seconds", "sim_speed")}
    return (summary, run.waits, run.predicted, run.snapshots)


def test_same_seed_same_result_in_parallel_processes(
    persons_result: CosimResult, small_spec: CosimSpec, tmp_path: Path
) -> None:
    again = run_cosim(replace(small_spec, workers=2), out_dir=tmp_path, progress=False)
    first = {r.policy: _outcome(r) for r in persons_result.runs}
    second = {r.policy: _outcome(r) for r in again.runs}
    assert first == second
    assert again.curves == persons_result.curves


def test_incidents_same_seed_same_result(
    incidents_result: CosimResult, small_spec: CosimSpec, tmp_path: Path
) -> None:
    spec = replace(
        small_spec,
        mode="incidents",
        policies=parse_policies("sa,sumo-stop"),
        history=50,
        workers=2,
    )
    again = run_cosim(spec, out_dir=tmp_path, progress=False)
    first = {
        r.policy: _outcome(r) for r in incidents_result.runs if r.policy in ("sa", "sumo-stop")
    }
    assert {r.policy: _outcome(r) for r in again.runs} == first


def test_another_seed_other_requests(
    persons_result: CosimResult, small_spec: CosimSpec, tmp_path: Path
) -> None:
    other = run_cosim(
        replace(small_spec, seeds=(4,), policies=parse_policies("sumo-stop")),
        out_dir=tmp_path,
        progress=False,
    )
    (mine,) = persons_result.by_policy()["sumo-stop"]
    (theirs,) = other.runs
    assert [t for t, _, _ in mine.waits] != [t for t, _, _ in theirs.waits]


def test_resume_reuses_the_saved_runs(small_spec: CosimSpec, tmp_path: Path) -> None:
    spec = replace(small_spec, policies=parse_policies("sa,sumo-stop"), duration=300.0)
    first = run_cosim(spec, out_dir=tmp_path, progress=False, resume=True)
    saved = sorted(p.name for p in (tmp_path / "seed3").glob("run-*.json"))
    assert saved == ["run-sa.json", "run-sumo-stop.json"]
    again = run_cosim(spec, out_dir=tmp_path, progress=False, resume=True)
    assert [r.to_json() for r in again.runs] == [r.to_json() for r in first.runs]
    longer = run_cosim(replace(spec, duration=360.0), out_dir=tmp_path, progress=False, resume=True)
    assert [r.requests for r in longer.runs] != [] and longer.spec.duration == 360.0
    assert [r.sim_seconds for r in longer.runs] == [spec.end + 60.0] * 2
