"""A co-simulation experiment: several policies on identical demand, several seeds.

:func:`run_cosim` is the Python API beneath ``routing-svc cosim``::

    from routing_svc.sim import CosimSpec, run_cosim
    result = run_cosim(CosimSpec(network="drt", vehicles=10, seeds=(0, 1, 2)),
                       out_dir=Path("out/cosim"))
    result.summary()["policies"]["sa"]["mean_wait_s"]

For each seed it writes the shared inputs (background traffic, the request
stream as SUMO persons), then runs every policy as its own SUMO process (a
pool of ``workers`` processes; libsumo allows one simulation per process),
reads SUMO's outputs and evaluates the SA objective over time exactly against
the true demand distribution (for incidents, a large sample of it recorded in the
same traffic).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from routing_svc.errors import InvalidInput
from routing_svc.json_text import json_text
from routing_svc.sim.measures import PolicyRun
from routing_svc.sim.policies import floored_step
from routing_svc.sim.prepare import Prepared, cosim_stands, prepare_seeds
from routing_svc.sim.run import PolicyJob, process_map, run_saved
from routing_svc.sim.scenario import Optimum
from routing_svc.sim.spec import CosimSpec

__all__ = ["CosimResult", "CosimSpec", "run_cosim"]


@dataclass(slots=True)
class CosimResult:
    """Every run, the optimum and the SA objective over time."""

    spec: CosimSpec
    runs: list[PolicyRun]
    optimum: dict[int, Optimum | None]
    """Per seed: the p-median the ``optimum`` policy used (and the SA aims for)."""
    curves: dict[tuple[str, int], list[tuple[float, float]]] = field(default_factory=dict)
    """``(policy, seed)`` -> ``(time, exact expected free-flow wait)`` over the run."""
    optimum_curve: dict[int, list[tuple[float, float]]] = field(default_factory=dict)
    """Per seed: the optimum's expected wait for the demand in force over time."""
    start: dict[int, list[tuple[str, float]]] = field(default_factory=dict)
    prepared: Prepared | None = None
    """The network, demand and per-seed inputs (for plots; not serialised)."""

    def by_policy(self) -> dict[str, list[PolicyRun]]:
        out: dict[str, list[PolicyRun]] = {}
        for run in self.runs:
            out.setdefault(run.policy, []).append(run)
        return out

    def summary(self) -> dict[str, Any]:
        """JSON-ready: per policy, the means over seeds and each seed's numbers."""
        policies = {}
        for name, runs in self.by_policy().items():
            rows = [r.summary() for r in sorted(runs, key=lambda r: r.seed)]
            keys = [k for k, v in rows[0].items() if isinstance(v, int | float) and k != "seed"]
            mean: dict[str, Any] = {k: float(np.nanmean([row[k] for row in rows])) for k in keys}
            mean["within"] = {
                limit: float(np.nanmean([row["within"][limit] for row in rows]))
                for limit in rows[0]["within"]
            }
            curves = [self.curves[(name, r.seed)] for r in runs if (name, r.seed) in self.curves]
            if curves:
                mean["final_expected_wait_s"] = float(np.mean([c[-1][1] for c in curves]))
            policies[name] = {**mean, "seeds": rows}
        optimum = {
            str(seed): None
            if opt is None
            else {
                "expected_wait_s": opt.expected_cost,
                "method": opt.method,
                "proven_optimal": opt.proven_optimal,
            }
            for seed, opt in self.optimum.items()
        }
        summary = {"spec": self.spec.to_dict(), "policies": policies, "optimum": optimum}
        signals = self.prepared.signals if self.prepared is not None else None
        if signals is not None:
            summary["signals"] = signals.to_dict()
        reading = self.prepared.stands if self.prepared is not None else None
        if reading is not None:
            summary["stands"] = {
                "file": self.spec.stands,
                "usable": len(reading.usable),
                "dropped": len(reading.dropped),
                "capacity": reading.capacity,
            }
        return summary


def _jobs(spec: CosimSpec, prepared: Prepared, *, progress: bool, resume: bool) -> list[PolicyJob]:
    """One job per seed and policy, in that order."""
    single = len(spec.seeds) * len(spec.policies) == 1
    jobs = []
    for seed_inputs in prepared.seeds:
        for policy in spec.policies:
            positions = (
                seed_inputs.optimum_vehicles
                if policy.positions == "optimum"
                else seed_inputs.start_vehicles
            )
            if positions is None:
                raise InvalidInput("the optimum policy needs the optimum positions")
            step = (
                floored_step(typical_cost=prepared.typical_cost, vehicles=spec.vehicles)
                if policy.floor
                else None
            )
            history = seed_inputs.history if policy.history else ()
            jobs.append(
                PolicyJob(
                    policy=policy,
                    seed=seed_inputs.seed,
                    net=prepared.net,
                    routes=seed_inputs.routes,
                    workdir=seed_inputs.workdir,
                    vehicles=positions,
                    end=spec.end,
                    measure_from=spec.warmup,
                    request_end=spec.warmup + spec.duration,
                    cost=spec.cost,
                    step=step,
                    history=tuple((r.edge, r.offset) for r in history),
                    traffic_period=spec.traffic_period,
                    service_url=spec.service_url,
                    backend=spec.backend,
                    gui=spec.gui,
                    snapshot_period=spec.snapshot_period,
                    rule=spec.rule,
                    stands=prepared.stands.usable if prepared.stands is not None else (),
                    stands_file=None if spec.stands is None else Path(spec.stands).resolve(),
                    move_up=spec.move_up,
                    queue_order=spec.queue_order,
                    progress=progress and (single or spec.gui),
                    resume=resume,
                )
            )
    return jobs


def run_cosim(
    spec: CosimSpec, *, out_dir: Path, progress: bool = True, resume: bool = False
) -> CosimResult:
    """Run every policy of ``spec`` on every seed; write ``summary.json`` into ``out_dir``.

    Parameters
    ----------
    spec : CosimSpec
        The experiment.
    out_dir : Path
        Inputs, SUMO outputs, ``summary.json`` and ``runs.json`` go here.
    progress : bool
        Show progress bars (a bar over runs; in a single run, over simulated time).
    resume : bool
        Reuse every run saved in ``out_dir`` for the same inputs (each run is
        saved as ``seed<k>/run-<policy>.json`` when it ends; inputs are
        prepared again, deterministically).

    Returns
    -------
    CosimResult
    """
    stands = cosim_stands(spec)  # a bad stands file fails before anything is written
    out_dir = out_dir.resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    prepared = prepare_seeds(spec, out_dir=out_dir, progress=progress, stands=stands)
    warning = prepared.signals.warning(spec.network) if prepared.signals is not None else None
    if warning is not None:
        print(warning, file=sys.stderr)
    jobs = _jobs(spec, prepared, progress=progress, resume=resume)
    workers = 1 if spec.gui else min(spec.workers, len(jobs))
    runs = process_map(
        run_saved, jobs, workers=workers, progress=progress and len(jobs) > 1, desc="runs"
    )
    (out_dir / "runs.json").write_text(
        json_text({"spec": spec.to_dict(), "runs": [r.to_json() for r in runs]}) + "\n",
        encoding="utf-8",
    )
    curves, optimum_curve = prepared.evaluate(runs)
    result = CosimResult(
        spec=spec,
        runs=runs,
        optimum={s.seed: s.optimum for s in prepared.seeds},
        curves=curves,
        optimum_curve=optimum_curve,
        start={s.seed: [(v.edge, v.offset) for v in s.start_vehicles] for s in prepared.seeds},
        prepared=prepared,
    )
    (out_dir / "summary.json").write_text(
        json_text(result.summary(), indent=2) + "\n", encoding="utf-8"
    )
    return result
