"""The shared inputs of every seed, and the exact objective of the runs afterwards.

:func:`prepare_seeds` writes, per seed, the background traffic and the
request stream (for ``incidents``, recorded in a SUMO run of the background
traffic alone, in a worker process), draws the start positions and the
historical requests, and solves the p-median that the ``optimum`` policy
uses: for ``persons``, of the known demand mixture; for ``incidents``, of
``spec.incident_sample`` incidents recorded in the same background-only run
as the evaluation stream but drawn apart from it (an estimate of the incident
distribution: a p-median of the very incidents to be served would place
vehicles with hindsight). :meth:`Prepared.evaluate` turns the recorded
reference positions of each run into the exact expected free-flow wait under
the demand in force (the SA objective over time).

History: the requests of an earlier period that the ``sa`` policy learns from
before the run (as a deployed service would have). For ``persons`` they are
drawn from the first demand phase with ``default_rng([seed, 5])``; for
``incidents`` they are recorded like the evaluation stream, in another
background traffic realisation (randomTrips seed ``seed + 1000``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork, RoadSpace, load_network
from routing_svc.network.signals import SignalAudit, audit_signals
from routing_svc.network.stands import StandReading, usable_stands
from routing_svc.sim.backend import make_backend
from routing_svc.sim.inputs import FleetVehicle, Request, random_trips, sumo_options, write_persons
from routing_svc.sim.measures import PolicyRun
from routing_svc.sim.requests import Destinations, Phase, incident_requests, person_requests
from routing_svc.sim.run import process_map
from routing_svc.sim.scenario import (
    Optimum,
    build_demand,
    demand_at,
    demand_profile,
    empirical_demand,
    expected_wait,
    fleet_vehicles,
    mixed_demand,
    solve_optimum,
    solve_stand_optimum,
    start_positions,
)
from routing_svc.sim.spec import CosimSpec
from routing_svc.types import NetPosition

__all__ = [
    "IncidentJob",
    "Prepared",
    "SeedInputs",
    "cosim_stands",
    "prepare_seeds",
    "record_incidents",
]

Curve = list[tuple[float, float]]
"""``(time, exact expected free-flow wait)`` points."""

#: randomTrips seed offset of the traffic in which incident history is recorded.
HISTORY_SEED_OFFSET = 1000


@dataclass(frozen=True, slots=True)
class SeedInputs:
    """What every policy of one seed shares."""

    seed: int
    workdir: Path
    routes: tuple[Path, ...]
    requests: tuple[Request, ...]
    history: tuple[Request, ...]
    start_vehicles: tuple[FleetVehicle, ...]
    optimum_vehicles: tuple[FleetVehicle, ...] | None
    optimum: Optimum | None
    demand_sample: tuple[Request, ...] = ()
    """``incidents``: the incidents recorded apart, whose p-median is ``optimum``."""


@dataclass(frozen=True, slots=True)
class IncidentJob:
    """A background-only SUMO run that records incidents (picklable)."""

    net: Path
    trips: Path
    seed: int
    rate: float
    start: float
    end: float
    ride_radius: float
    tripinfo: Path
    stream: int = 1
    """The random stream of the incidents' times and vehicles (``default_rng([seed,
    stream])``): the evaluation stream and the distribution sample of one run differ."""


def record_incidents(job: IncidentJob) -> list[Request]:
    """Run the background traffic alone and record incidents at its vehicles' places.

    The incidents are saved beside SUMO's output (``<tripinfo>.incidents.json``)
    and reused while the job is unchanged: they are a deterministic function of it.
    """
    saved = job.tripinfo.with_suffix(".incidents.json")
    digest = hashlib.sha256(job.trips.read_bytes()).hexdigest()
    key = json.dumps([dataclasses.astuple(job), digest], default=str)
    if saved.is_file():
        data = json.loads(saved.read_text(encoding="utf-8"))
        if data.get("key") == key:
            return [Request(*item) for item in data["requests"]]
    requests = _record(job)
    saved.write_text(
        json.dumps({"key": key, "requests": [dataclasses.astuple(r) for r in requests]}),
        encoding="utf-8",
    )
    return requests


def _record(job: IncidentJob) -> list[Request]:
    from routing_svc.demand import uniform_by_length

    network = load_network(job.net)
    destinations = Destinations(network, uniform_by_length(network), radius=job.ride_radius)
    backend = make_backend("libsumo")
    backend.start(
        sumo_options(
            net=job.net,
            routes=[job.trips],
            end=job.end,
            seed=job.seed,
            tripinfo=job.tripinfo,
            dispatch="greedy",
        )
    )
    try:
        return incident_requests(
            backend,
            network,
            destinations,
            rng=np.random.default_rng([job.seed, job.stream]),
            rate_per_hour=job.rate,
            start=job.start,
            end=job.end,
        )
    finally:
        backend.close()


def _background(net: Path, trips: Path, *, seed: int, end: float, density: float) -> Path:
    """randomTrips' file for this seed, reused while its parameters are unchanged."""
    stamp = trips.with_suffix(".json")
    params = {"net": str(net), "seed": seed, "end": end, "density": density}
    if trips.is_file() and stamp.is_file() and json.loads(stamp.read_text()) == params:
        return trips
    random_trips(net, trips, seed=seed, end=end, density=density)
    stamp.write_text(json.dumps(params))
    return trips


@dataclass
class Prepared:
    """The network, demand phases and per-seed inputs of an experiment."""

    spec: CosimSpec
    net: Path
    network: CompiledNetwork
    space: RoadSpace
    phases: list[Phase] | None
    seeds: list[SeedInputs]
    stands: StandReading | None = None
    """The usable stands of ``spec.stands``, if given."""
    signals: SignalAudit | None = None
    """The network's traffic lights as SUMO runs them (links never green)."""
    _sampled: dict[int, DemandDistribution[NetPosition]] = dataclasses.field(
        default_factory=dict, repr=False
    )
    """``incidents``: each seed's distribution sample as a demand, built once."""

    @property
    def typical_cost(self) -> float:
        return self.space.typical_cost()

    def _decode(self, positions: dict[str, tuple[str, float]]) -> list[NetPosition]:
        index = self.network.edge_index
        return [NetPosition(index[e], float(o)) for _, (e, o) in sorted(positions.items())]

    def _demand(self, seed: SeedInputs, time: float) -> DemandDistribution[NetPosition]:
        if self.phases is not None:
            return demand_at(self.phases, time)
        return self.incident_demand(seed.seed, seed.demand_sample or seed.requests)

    def incident_demand(
        self, seed: int, incidents: Sequence[Request]
    ) -> DemandDistribution[NetPosition]:
        """``incidents`` (a seed's distribution sample) as a demand, built once per seed."""
        demand = self._sampled.get(seed)
        if demand is None:
            demand = self._sampled[seed] = empirical_demand(self.network, incidents)
        return demand

    def optimum_for(self, demand: DemandDistribution[NetPosition]) -> Optimum:
        """The p-median of ``demand``, over the stands if there are any."""
        if self.stands is None:
            return solve_optimum(self.space, demand, self.spec.vehicles)
        stands = self.stands.stand_set(self.network)
        return solve_stand_optimum(self.space, demand, self.spec.vehicles, stands)

    def evaluate(
        self, runs: Sequence[PolicyRun]
    ) -> tuple[dict[tuple[str, int], Curve], dict[int, Curve]]:
        """The exact expected waits over time of the runs' recorded reference positions,
        per ``(policy, seed)``, and of the optimum for the demand in force, per seed."""
        curves: dict[tuple[str, int], Curve] = {}
        optimum_curve: dict[int, Curve] = {}
        by_seed = {s.seed: s for s in self.seeds}
        for run in runs:
            if run.snapshots:
                seed = by_seed[run.seed]
                curves[(run.policy, run.seed)] = [
                    (t, expected_wait(self.space, self._decode(pos), self._demand(seed, t)))
                    for t, pos in run.snapshots
                ]
        phase_optima: dict[float, float] = {}
        if self.phases is not None and len(self.phases) > 1:
            for phase in self.phases:
                best = self.optimum_for(phase.demand)
                phase_optima[phase.start] = best.expected_cost
        for seed in self.seeds:
            if seed.optimum is None:
                continue
            times = sorted({t for r in runs if r.seed == seed.seed for t, _ in r.snapshots})
            if not phase_optima:
                optimum_curve[seed.seed] = [(t, seed.optimum.expected_cost) for t in times]
                continue
            first = min(phase_optima)
            optimum_curve[seed.seed] = [
                (t, phase_optima[max((s for s in phase_optima if s <= t), default=first)])
                for t in times
            ]
        return curves, optimum_curve


def _phases(spec: CosimSpec, network: CompiledNetwork) -> list[Phase]:
    """The demand distribution(s) of a ``persons`` run (the hotspots move at ``shift_at``)."""
    first = build_demand(network, spec.demand, rng=np.random.default_rng([spec.demand_seed, 3]))
    phases = [Phase(0.0, first)]
    if spec.shift_at is not None:
        moved = build_demand(network, spec.demand, rng=np.random.default_rng([spec.demand_seed, 4]))
        phases.append(Phase(spec.warmup + spec.shift_at, moved))
    return phases


def _incidents(
    spec: CosimSpec, net: Path, workdirs: dict[int, Path], trips: dict[int, Path], *, progress: bool
) -> tuple[dict[int, list[Request]], dict[int, list[Request]], dict[int, list[Request]]]:
    """Recorded incident streams of every seed, in parallel: the evaluation stream, the
    distribution sample (the same traffic, another random stream) and the history."""
    start, stop = spec.warmup, spec.warmup + spec.duration
    jobs = [
        IncidentJob(
            net,
            trips[s],
            s,
            spec.rate,
            start,
            stop,
            spec.ride_radius,
            workdirs[s] / "tripinfo-background.xml",
        )
        for s in spec.seeds
    ]
    sample_rate = spec.incident_sample * 3600.0 / spec.duration
    jobs += [
        IncidentJob(
            net,
            trips[s],
            s,
            sample_rate,
            start,
            stop,
            spec.ride_radius,
            workdirs[s] / "tripinfo-sample.xml",
            stream=2,
        )
        for s in spec.seeds
    ]
    if spec.history > 0:
        rate = spec.history * 3600.0 / spec.duration
        for s in spec.seeds:
            other = _background(
                net,
                workdirs[s] / "history.trips.xml",
                seed=s + HISTORY_SEED_OFFSET,
                end=spec.end,
                density=spec.density,
            )
            jobs.append(
                IncidentJob(
                    net,
                    other,
                    s + HISTORY_SEED_OFFSET,
                    rate,
                    start,
                    stop,
                    spec.ride_radius,
                    workdirs[s] / "tripinfo-history.xml",
                )
            )
    recorded = process_map(
        record_incidents,
        jobs,
        workers=min(spec.workers, len(jobs)),
        progress=progress,
        desc="incidents",
    )
    n = len(spec.seeds)
    requests = dict(zip(spec.seeds, recorded[:n], strict=True))
    sample = dict(zip(spec.seeds, recorded[n : 2 * n], strict=True))
    history = dict(zip(spec.seeds, recorded[2 * n :], strict=True)) if spec.history > 0 else {}
    return requests, sample, history


def cosim_stands(spec: CosimSpec) -> StandReading | None:
    """The usable stands of ``spec.stands`` on its network (``None`` without), holding
    the fleet (:func:`~routing_svc.network.stands.usable_stands`).

    Raises
    ------
    InvalidInput
        No such file, not an additional file, no usable stand, too little capacity.
    """
    if spec.stands is None:
        return None
    from routing_svc.network.catalogue import resolve_network

    network = load_network(resolve_network(spec.network))
    return usable_stands(Path(spec.stands), network, spec.vehicles)


def _at_stands(
    network: CompiledNetwork, optimum: Optimum, stands: StandReading | None
) -> tuple[FleetVehicle, ...]:
    """The fleet at the optimum's positions; with stands, each in a parkingArea there."""
    vehicles = fleet_vehicles(network, optimum.positions, prefix="fleet")
    if stands is None:
        return vehicles
    areas = {(s.edge, s.offset): s.id for s in stands.usable}
    return tuple(dataclasses.replace(v, area=areas[(v.edge, v.offset)]) for v in vehicles)


def prepare_seeds(
    spec: CosimSpec, *, out_dir: Path, progress: bool, stands: StandReading | None = None
) -> Prepared:
    """Write every seed's inputs under ``out_dir/seed<k>`` and solve the optimum
    (over ``stands``, the usable stands of ``spec.stands``, if given)."""
    from routing_svc.demand import uniform_by_length
    from routing_svc.network.catalogue import resolve_network

    net = resolve_network(spec.network).resolve()
    network = load_network(net)
    space = RoadSpace(network, cost=spec.cost)
    workdirs = {seed: out_dir / f"seed{seed}" for seed in spec.seeds}
    trips = {}
    for seed, workdir in workdirs.items():
        workdir.mkdir(parents=True, exist_ok=True)
        trips[seed] = _background(
            net, workdir / "background.trips.xml", seed=seed, end=spec.end, density=spec.density
        )
    phases = _phases(spec, network) if spec.mode == "persons" else None
    profile = demand_profile(spec.demand) if "?profile=" in spec.demand else None
    if profile is not None and phases is None:
        raise InvalidInput("a time-of-day profile applies to persons; incidents follow the traffic")
    start, stop = spec.warmup, spec.warmup + spec.duration
    if phases is not None:
        destinations = Destinations(network, uniform_by_length(network), radius=spec.ride_radius)
        requests = {
            s: person_requests(
                network,
                phases,
                destinations,
                rng=np.random.default_rng([s, 1]),
                rate_per_hour=spec.rate,
                start=start,
                end=stop,
                profile=profile,
            )
            for s in spec.seeds
        }
        history = {
            s: [
                Request(f"hist{i:06d}", 0.0, network.edge_ids[p.edge], float(p.offset), "", 0.0)
                for i, p in enumerate(
                    phases[0].demand.sample(np.random.default_rng([s, 5]), spec.history)
                )
            ]
            for s in spec.seeds
        }
        sample: dict[int, list[Request]] = {}
    else:
        requests, sample, history = _incidents(spec, net, workdirs, trips, progress=progress)
    prepared = Prepared(spec, net, network, space, phases, [], stands, audit_signals(net, network))
    shared: Optimum | None = None
    if phases is not None:
        shared = prepared.optimum_for(mixed_demand(phases, end=stop))
    seeds = []
    for seed in spec.seeds:
        persons = write_persons(workdirs[seed] / "requests.rou.xml", requests[seed])
        starts = start_positions(network, spec.vehicles, rng=np.random.default_rng([seed, 2]))
        optimum = shared
        if optimum is None and sample.get(seed):
            optimum = prepared.optimum_for(prepared.incident_demand(seed, sample[seed]))
        seeds.append(
            SeedInputs(
                seed=seed,
                workdir=workdirs[seed],
                routes=(trips[seed], persons),
                requests=tuple(requests[seed]),
                history=tuple(history.get(seed, ())),
                start_vehicles=fleet_vehicles(network, starts, prefix="fleet"),
                optimum_vehicles=None if optimum is None else _at_stands(network, optimum, stands),
                optimum=optimum,
                demand_sample=tuple(sample.get(seed, ())),
            )
        )
    prepared.seeds = seeds
    return prepared
