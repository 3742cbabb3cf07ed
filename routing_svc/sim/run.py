"""Co-simulation runs: one policy, one seed, one SUMO process; many in a process pool.

:func:`run_policy` is a plain function of a picklable :class:`PolicyJob`, so
several runs go to a process pool (libsumo allows one simulation per
process). Policies that the service dispatches (``sa``, ``sa-available``,
``sa-floor``, ``static``, ``optimum``) run with SUMO's ``traci`` dispatch
algorithm and a :class:`~routing_svc.sim.dispatcher.FleetDispatcher`; SUMO's
own policies run with its ``greedy`` dispatcher and nothing in the loop
(``sumo-taxistand`` with taxi stands at its start sites). Either way every
wait is read from SUMO's tripinfo output afterwards, and the fleet's load is
sampled from SUMO's taxi states (:class:`~routing_svc.sim.measures.FleetLoad`).
With stands (a parkingArea file), a run that uses them loads the file and
writes SUMO's stop output ``stops-<policy>.xml``, where every parking stop
names its parkingArea.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import multiprocessing
import sys
import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from routing_svc.client import FleetClient, HttpFleetClient
from routing_svc.json_text import json_text
from routing_svc.network.stands import Stand
from routing_svc.sim.backend import SimulationError, make_backend
from routing_svc.sim.dispatcher import FleetDispatcher, stand_homes
from routing_svc.sim.inputs import (
    FleetVehicle,
    passenger_lanes,
    sumo_options,
    write_fleet,
    write_stands_rerouter,
    write_taxi_stands,
)
from routing_svc.sim.measures import FleetLoad, PolicyRun, read_tripinfo
from routing_svc.sim.policies import Policy

__all__ = [
    "FLEET_PREFIX",
    "PolicyJob",
    "open_client",
    "process_map",
    "run_policy",
    "run_saved",
]

T = TypeVar("T")
R = TypeVar("R")

#: Fleet vehicle ids start with this (background vehicles start with ``bg``).
FLEET_PREFIX = "fleet"


@dataclass(frozen=True, slots=True, kw_only=True)
class PolicyJob:
    """Everything one run needs (picklable; paths are absolute).

    Attributes
    ----------
    policy : Policy
        What to run.
    seed : int
        SUMO's seed (the request stream and background traffic are in ``routes``).
    net : Path
        The SUMO network.
    routes : tuple of Path
        Background traffic and persons route files (shared by every policy).
    workdir : Path
        Where the run writes its fleet file and SUMO's tripinfo output.
    vehicles : tuple of FleetVehicle
        Ids and first reference positions (start or optimum).
    end : float
        Simulated seconds to run.
    measure_from : float
        Requests before this time are not counted in the mean waits.
    request_end : float, optional
        The end of the request period (``None``: ``end``); the load is
        measured in ``[measure_from, request_end)``.
    cost : str
        Fleet cost ``time`` or ``length``.
    step : Mapping, optional
        The fleet's step schedule (``None``: the service's default).
    history : tuple of (edge, offset)
        Historical requests: the fleet starts at their p-median (else at the
        vehicles' start positions).
    traffic_period : float, optional
        Push SUMO's live edge travel times every this many seconds.
    service_url : str, optional
        A running service; ``None`` runs it in-process.
    backend : str
        ``libsumo`` or ``traci``.
    gui : bool
        Show ``sumo-gui`` (TraCI).
    snapshot_period : float
        Seconds between records of the reference positions.
    progress : bool
        Show a progress bar over simulated time.
    resume : bool
        Reuse ``run-<policy>.json`` in ``workdir`` if it was saved for the same job.
    rule : str, optional
        The fleet's learning rule (``None``: the service's default).
    stands : tuple of Stand
        The usable stands of ``stands_file`` (parkingAreas).
    move_up : bool
        Idle vehicles wait at the service's posts (``GET .../posts``).
    queue_order : str
        Which waiting request is served next (:class:`~routing_svc.sim.dispatcher.FleetDispatcher`).
    stands_file : Path, optional
        A SUMO additional file with those parkingAreas: a policy that
        :attr:`~routing_svc.sim.policies.Policy.uses_stands` waits at them
        (the service's fleet is created with them as its ``stands``).
    """

    policy: Policy
    seed: int
    net: Path
    routes: tuple[Path, ...]
    workdir: Path
    vehicles: tuple[FleetVehicle, ...]
    end: float
    measure_from: float = 0.0
    request_end: float | None = None
    cost: str = "time"
    step: Mapping[str, Any] | None = None
    history: tuple[tuple[str, float], ...] = ()
    traffic_period: float | None = None
    service_url: str | None = None
    backend: str = "libsumo"
    gui: bool = False
    snapshot_period: float = 300.0
    progress: bool = False
    resume: bool = False
    rule: str | None = None
    stands: tuple[Stand, ...] = ()
    stands_file: Path | None = None
    move_up: bool = False
    queue_order: str = "soonest"

    @property
    def at_stands(self) -> bool:
        """Whether this run's vehicles wait at the stands of :attr:`stands_file`."""
        return self.stands_file is not None and self.policy.uses_stands

    def key(self) -> str:
        """What determines the run's result, as JSON (for reusing a saved run).

        It includes the SHA-256 of the network and route files, so a saved run
        is not reused for other requests or other traffic.
        """
        data = {
            name: getattr(self, name)
            for name in self.__dataclass_fields__
            if name not in ("progress", "resume", "gui", "backend", "service_url")
        }
        data["policy"] = dataclasses.asdict(self.policy)
        data["vehicles"] = [dataclasses.astuple(v) for v in self.vehicles]
        data["stands"] = [dataclasses.astuple(s) for s in self.stands]
        files = (self.net, *self.routes, *([self.stands_file] if self.stands_file else []))
        data["contents"] = [_digest(path) for path in files]
        return json.dumps(data, sort_keys=True, default=str)


def _digest(path: Path) -> str:
    """SHA-256 of a file's bytes."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def run_saved(job: PolicyJob) -> PolicyRun:
    """:func:`run_policy`, saving the result as ``run-<policy>.json`` in the job's folder.

    With ``job.resume``, a result saved for the same :meth:`PolicyJob.key` is
    returned instead of running SUMO again.
    """
    path = job.workdir / f"run-{job.policy.name}.json"
    key = job.key()
    if job.resume and path.is_file():
        saved = json.loads(path.read_text(encoding="utf-8"))
        if saved.get("key") == key:
            return PolicyRun.from_json(saved["run"])
    run = run_policy(job)
    path.write_text(json_text({"key": key, "run": run.to_json()}) + "\n", encoding="utf-8")
    return run


def open_client(service_url: str | None) -> FleetClient:
    """The fleet service: over HTTP at ``service_url``, else in this process."""
    if service_url:
        return HttpFleetClient(service_url)
    from routing_svc.service.inprocess import InProcessFleetClient

    return InProcessFleetClient()


def _close(client: FleetClient) -> None:
    close = getattr(client, "close", None)
    if callable(close):
        close()


def _fleet_spec(job: PolicyJob, network_id: str, fleet_id: str) -> dict[str, Any]:
    """The fleet of a policy the service dispatches.

    With history, the fleet starts at the p-median of the historical requests
    (the paper's deterministic first configuration, which the SA then
    refines); otherwise at the vehicles' start positions.
    """
    spec: dict[str, Any] = {
        "id": fleet_id,
        "network": network_id,
        "cost": job.cost,
        "objective": "routing",
        "step": dict(job.step) if job.step is not None else None,
        "seed": job.seed,
        "learning_vehicles": job.policy.learning_vehicles,
    }
    if job.rule is not None:
        spec["rule"] = job.rule
    if job.at_stands:
        spec["stands"] = [s.to_dict() for s in job.stands]
    if job.history:
        sample = [{"edge": edge, "offset": offset} for edge, offset in job.history]
        spec["vehicles"] = [{"id": v.id} for v in job.vehicles]
        spec["start"] = {"optimum": {"sample": sample}}
    else:
        spec["vehicles"] = [
            {"id": v.id, "position": {"edge": v.edge, "offset": v.offset}} for v in job.vehicles
        ]
    return spec


def _free_flow_times(net: Path) -> dict[str, float]:
    from routing_svc.network import load_network

    network = load_network(net)
    return {
        edge: float(network.length[i] / network.speed[i]) for i, edge in enumerate(network.edge_ids)
    }


def _network_id(net: Path) -> str:
    stem = net.name.split(".")[0]
    return "".join(c if c.isalnum() or c in "_.-" else "_" for c in stem)[:100] or "net"


def _loop(job: PolicyJob, step_once: Any) -> float:
    """Step until ``job.end``; return the wall-clock seconds it took."""
    from tqdm import tqdm

    started = time.perf_counter()
    with tqdm(
        total=int(job.end),
        disable=not job.progress,
        file=sys.stderr,
        unit="sim s",
        desc=f"{job.policy.name} seed {job.seed}",
        mininterval=0.5,
    ) as bar:
        done = 0.0
        while done < job.end:
            now = step_once()
            bar.update(int(now) - int(done))
            done = now
    return time.perf_counter() - started


def run_policy(job: PolicyJob) -> PolicyRun:
    """Run one policy in SUMO and read what SUMO measured."""
    job.workdir.mkdir(parents=True, exist_ok=True)
    name = job.policy.name
    by_service = job.policy.dispatch == "service"
    tripinfo = job.workdir / f"tripinfo-{name}.xml"
    backend = make_backend(job.backend, gui=job.gui)
    client = open_client(job.service_url) if by_service else None
    fleet_id = f"cosim-{name}-{job.seed}-{uuid.uuid4().hex[:8]}"
    dispatcher: FleetDispatcher | None = None
    try:
        vehicles = job.vehicles
        if client is not None:
            network_id = str(client.add_network(job.net, name=_network_id(job.net))["id"])
            client.create_fleet(_fleet_spec(job, network_id, fleet_id))
            fleet = client.get_fleet(fleet_id)
            vehicles = (
                _inserted_at_stands(fleet, job.vehicles, job.stands)
                if job.at_stands
                else _inserted_at_references(fleet, job.vehicles)
            )
        lengths = _edge_lengths(job.net)
        stands = job.policy.idle == "taxistand"
        fleet_file = write_fleet(
            job.workdir / f"fleet-{name}.rou.xml",
            vehicles,
            lengths=lengths,
            park=by_service,
            stands=stands,
        )
        additional = []
        if job.at_stands:
            assert job.stands_file is not None
            additional.append(job.stands_file)
            if stands:
                additional.append(
                    write_stands_rerouter(
                        job.workdir / f"stands-{name}.add.xml",
                        [s.id for s in job.stands],
                        [s.edge for s in job.stands],
                    )
                )
        elif stands:
            additional.append(
                write_taxi_stands(
                    job.workdir / f"stands-{name}.add.xml",
                    vehicles,
                    lengths=lengths,
                    lanes=passenger_lanes(job.net, [v.edge for v in vehicles]),
                    capacity=len(vehicles),
                )
            )
        options = sumo_options(
            net=job.net,
            routes=[*job.routes, fleet_file],
            end=job.end,
            seed=job.seed,
            tripinfo=tripinfo,
            dispatch="traci" if by_service else job.policy.algorithm,
            idle=job.policy.idle,
            additional=additional,
            stops=job.workdir / f"stops-{name}.xml" if job.at_stands else None,
        )
        backend.start(options)
        request_end = job.end if job.request_end is None else job.request_end
        load = FleetLoad([v.id for v in vehicles], since=job.measure_from, until=request_end)
        if client is not None:
            dispatcher = FleetDispatcher(
                backend,
                client,
                fleet_id,
                learn=job.policy.learn,
                edge_lengths=lengths,
                traffic_edges=_free_flow_times(job.net) if job.traffic_period else None,
                traffic_period=job.traffic_period or 60.0,
                snapshot_period=job.snapshot_period,
                stands=job.stands if job.at_stands else None,
                move_up=job.move_up,
                queue_order=job.queue_order,
            )

        def step_once() -> float:
            backend.step()
            if dispatcher is not None:
                dispatcher.on_step()
            load.sample(backend)
            return backend.time()

        wall = _loop(job, step_once)
        if dispatcher is not None:
            dispatcher.finish()
    except SimulationError:
        raise
    except Exception as exc:  # SUMO's own exceptions do not cross process boundaries
        raise SimulationError(f"{name} seed {job.seed}: {type(exc).__name__}: {exc}") from None
    finally:
        backend.close()
        if client is not None:
            with contextlib.suppress(Exception):  # best effort, e.g. on a server we do not own
                client.delete_fleet(fleet_id)
            _close(client)
    return _result(job, tripinfo, dispatcher, wall, load)


def _inserted_at_references(
    fleet: Mapping[str, Any], vehicles: Sequence[FleetVehicle]
) -> tuple[FleetVehicle, ...]:
    """The SUMO vehicles of a service fleet, inserted at the fleet's reference positions.

    A fleet that starts from the p-median of its history has references other
    than the job's start positions; its vehicles begin the run parked there,
    exactly like the ``optimum`` policy's vehicles at their sites, so the
    policies differ in where their references go and not in a first drive.
    """
    references = {
        str(v["id"]): (str(v["position"]["edge"]), float(v["position"]["offset"]))
        for v in fleet["vehicles"]
    }
    return tuple(
        FleetVehicle(v.id, *references[v.id]) if v.id in references else v for v in vehicles
    )


def _inserted_at_stands(
    fleet: Mapping[str, Any], vehicles: Sequence[FleetVehicle], stands: Sequence[Stand]
) -> tuple[FleetVehicle, ...]:
    """The SUMO vehicles of a fleet with stands, each parked in its stand's parkingArea
    (:func:`~routing_svc.sim.dispatcher.stand_homes`)."""
    homes = stand_homes(fleet, stands)
    return tuple(
        FleetVehicle(v.id, area.edge, area.offset, area=area.id)
        for v in vehicles
        for _, area in [homes[v.id]]
    )


def _edge_lengths(net: Path) -> dict[str, float]:
    """Every edge of the network as the service sees it, and its length (m)."""
    from routing_svc.network import load_network

    network = load_network(net)
    return {e: float(network.length[i]) for i, e in enumerate(network.edge_ids)}


def _result(
    job: PolicyJob,
    tripinfo: Path,
    dispatcher: FleetDispatcher | None,
    wall: float,
    load: FleetLoad,
) -> PolicyRun:
    measures = read_tripinfo(tripinfo, fleet_prefix=FLEET_PREFIX)
    request_end = job.end if job.request_end is None else job.request_end
    requested = [r for r in measures.rides if job.measure_from <= r.requested < request_end]
    last = max((r.requested for r in requested), default=job.measure_from)
    half = job.measure_from + (last - job.measure_from) / 2.0
    log = dispatcher.log if dispatcher is not None else None
    return PolicyRun(
        policy=job.policy.name,
        seed=job.seed,
        requests=len(requested),
        served=sum(1 for r in requested if r.served),
        mean_wait=measures.mean_wait(since=job.measure_from),
        mean_wait_second_half=measures.mean_wait(since=half),
        empty_km=measures.empty_km,
        driven_km=measures.driven_km,
        fallbacks=sum(1 for p, v in log.dispatched.items() if log.named.get(p) != v) if log else 0,
        queued=log.queued if log else 0,
        failed=log.failed if log else 0,
        sim_seconds=job.end,
        wall_seconds=wall,
        tripinfo=str(tripinfo),
        measure_from=job.measure_from,
        vehicles=len(job.vehicles),
        request_hours=(request_end - job.measure_from) / 3600.0,
        busy_fraction=load.busy_fraction,
        state_batches=log.state_batches if log else 0,
        traffic_updates=log.traffic_updates if log else 0,
        park_retries=log.park_retries if log else 0,
        unparked=log.unparked if log else 0,
        lost=sum(1 for f in measures.fleet if f.left),
        waits=[(r.requested, r.wait, r.served) for r in measures.rides],
        predicted=[
            (
                log.predicted.get(r.person, math.nan),
                log.dispatched.get(r.person) != log.named.get(r.person),
            )
            for r in measures.rides
        ]
        if log
        else [],
        snapshots=[(s.time, s.positions) for s in log.snapshots] if log else [],
    )


def process_map(
    function: Callable[[T], R],
    items: Sequence[T],
    *,
    workers: int,
    progress: bool,
    desc: str,
) -> list[R]:
    """``[function(item) for item in items]``, on ``workers`` spawned processes.

    Processes are spawned (not forked), so none inherits a running SUMO; with
    ``workers == 1`` everything runs in this process, one job after another.
    A bar counts finished jobs when ``progress`` is true.
    """
    from tqdm import tqdm

    if not items:
        return []
    with tqdm(
        total=len(items), disable=not progress, file=sys.stderr, desc=desc, unit="run"
    ) as bar:
        if workers <= 1:
            results = []
            for item in items:
                results.append(function(item))
                bar.update(1)
            return results
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
            futures = [pool.submit(function, item) for item in items]
            for future in futures:
                future.add_done_callback(lambda _: bar.update(1))
            return [f.result() for f in futures]
