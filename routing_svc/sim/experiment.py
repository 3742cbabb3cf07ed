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
the true (or, for incidents, the realised) demand distribution.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from routing_svc.errors import InvalidInput
from routing_svc.sim.measures import PolicyRun
from routing_svc.sim.policies import DEFAULT_POLICIES, POLICIES, Policy, floored_step
from routing_svc.sim.run import PolicyJob, process_map, run_saved
from routing_svc.sim.scenario import Optimum

if TYPE_CHECKING:
    from routing_svc.sim.prepare import Prepared

__all__ = ["CosimResult", "CosimSpec", "run_cosim"]


@dataclass(frozen=True, slots=True, kw_only=True)
class CosimSpec:
    """What to simulate (keyword-only; everything but ``network`` has a default).

    Attributes
    ----------
    network : str
        A network name (``grid``, ``drt``, ...) or a ``.net.xml[.gz]`` path.
    mode : {"persons", "incidents"}
        Where requests come from (see :mod:`routing_svc.sim.requests`).
    vehicles : int
        Fleet size.
    duration : float
        Simulated seconds during which requests are made.
    warmup : float
        Seconds of background traffic before the first request.
    drain : float
        Seconds simulated after the last request (to serve it).
    rate : float
        Requests per hour.
    demand : str
        ``persons``: ``uniform``, ``hotspots[:K]`` or an edge-weights file.
    demand_seed : int
        Seed of the hotspot layout (shared by all seeds).
    shift_at : float, optional
        ``persons``: seconds after the first request when the hotspots move.
    ride_radius : float
        Rides end within this straight-line distance (m) of the request, if possible.
    history : int
        Historical requests that ``sa`` and ``sa-floor`` learn from before the run.
    density : float
        Background traffic: randomTrips' insertion density (vehicles per hour
        and km of road).
    traffic_period : float, optional
        Push SUMO's edge travel times to the fleet every this many seconds.
    cost : {"time", "length"}
        The fleet's cost (``time``: free-flow, or live with ``traffic_period``).
    policies : tuple of Policy
        What to compare.
    seeds : tuple of int
        One replication per seed.
    service_url : str, optional
        A running service instead of the in-process one.
    backend : {"libsumo", "traci"}
        How to run SUMO; ``gui`` implies traci.
    gui : bool
        Show ``sumo-gui`` (runs one at a time).
    workers : int
        Parallel SUMO processes.
    snapshot_period : float
        Seconds between records of the reference positions.
    rule : str, optional
        The learning rule of the service's fleets (``consolidating``, ``probe`` or
        ``paper``; ``None``: the service's default).
    """

    network: str
    mode: Literal["persons", "incidents"] = "persons"
    vehicles: int = 10
    duration: float = 7200.0
    warmup: float = 600.0
    drain: float = 900.0
    rate: float = 60.0
    demand: str = "hotspots:3"
    demand_seed: int = 1
    shift_at: float | None = None
    ride_radius: float = 1500.0
    history: int = 0
    density: float = 10.0
    traffic_period: float | None = None
    cost: Literal["time", "length"] = "time"
    policies: tuple[Policy, ...] = tuple(POLICIES[n] for n in DEFAULT_POLICIES)
    seeds: tuple[int, ...] = (0,)
    service_url: str | None = None
    backend: str = "libsumo"
    gui: bool = False
    workers: int = 2
    snapshot_period: float = 300.0
    rule: str | None = None

    def __post_init__(self) -> None:
        if self.mode not in ("persons", "incidents"):
            raise InvalidInput(f"mode must be 'persons' or 'incidents', got {self.mode!r}")
        if self.vehicles < 1 or not self.seeds or not self.policies or self.workers < 1:
            raise InvalidInput("need >= 1 vehicle, seed, policy and worker")
        if self.history < 0:
            raise InvalidInput("history must be >= 0")
        for name in ("duration", "rate", "density", "ride_radius"):
            if not math.isfinite(getattr(self, name)) or getattr(self, name) <= 0.0:
                raise InvalidInput(f"{name} must be a finite number > 0")
        if self.warmup < 0.0 or self.drain < 0.0:
            raise InvalidInput("warmup and drain must be >= 0")
        if self.shift_at is not None and not 0.0 < self.shift_at < self.duration:
            raise InvalidInput("shift_at must lie inside the request period")
        if self.mode == "incidents" and self.shift_at is not None:
            raise InvalidInput("shift_at applies to persons only")
        if self.traffic_period is not None and (
            self.cost != "time" or not self.traffic_period > 0.0
        ):
            raise InvalidInput("traffic_period needs cost 'time' and a period > 0")

    @property
    def end(self) -> float:
        """The simulation's last second."""
        return self.warmup + self.duration + self.drain

    def to_dict(self) -> dict[str, Any]:
        data = {k: getattr(self, k) for k in self.__dataclass_fields__}
        data["policies"] = [p.name for p in self.policies]
        data["seeds"] = list(self.seeds)
        return data


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
            mean = {k: float(np.nanmean([row[k] for row in rows])) for k in keys}
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
        return {"spec": self.spec.to_dict(), "policies": policies, "optimum": optimum}


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
                    cost=spec.cost,
                    step=step,
                    history=tuple((r.edge, r.offset) for r in history),
                    traffic_period=spec.traffic_period,
                    service_url=spec.service_url,
                    backend=spec.backend,
                    gui=spec.gui,
                    snapshot_period=spec.snapshot_period,
                    rule=spec.rule,
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
    from routing_svc.sim.prepare import prepare_seeds

    out_dir = out_dir.resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    prepared = prepare_seeds(spec, out_dir=out_dir, progress=progress)
    jobs = _jobs(spec, prepared, progress=progress, resume=resume)
    workers = 1 if spec.gui else min(spec.workers, len(jobs))
    runs = process_map(
        run_saved, jobs, workers=workers, progress=progress and len(jobs) > 1, desc="runs"
    )
    (out_dir / "runs.json").write_text(
        json.dumps({"spec": spec.to_dict(), "runs": [r.to_json() for r in runs]}) + "\n",
        encoding="utf-8",
    )
    result = CosimResult(
        spec=spec,
        runs=runs,
        optimum={s.seed: s.optimum for s in prepared.seeds},
        start={s.seed: [(v.edge, v.offset) for v in s.start_vehicles] for s in prepared.seeds},
        prepared=prepared,
    )
    prepared.evaluate(result)
    (out_dir / "summary.json").write_text(
        json.dumps(result.summary(), indent=2, allow_nan=True) + "\n", encoding="utf-8"
    )
    return result
