"""The demo fleet that the quick start shows, and a feeder of demo targets."""

from __future__ import annotations

import asyncio
import logging

import numpy as np
from starlette.concurrency import run_in_threadpool

from routing_svc.errors import Conflict, RoutingSvcError, UnknownFleet
from routing_svc.service.fleets import FleetService
from routing_svc.service.networks import NetworkEntry
from routing_svc.service.schemas import DemandSpec, EdgePosition, FleetSpec, TargetSpec, VehicleSpec

DEMO_FLEET = "demo"
DEMO_VEHICLES = 8
DEMO_DEMAND = DemandSpec(kind="hotspots", count=3, seed=7)

log = logging.getLogger("routing_svc.demo")


def ensure_demo_fleet(service: FleetService, entry: NetworkEntry) -> None:
    """Create the demo fleet (8 vehicles on random edges, hotspot demand) if it never existed.

    A demo fleet that was deleted stays deleted (fleet ids are never reused), and one that
    another instance on the same store created meanwhile is left as it is.
    """
    try:
        service.get_fleet(DEMO_FLEET)
        return
    except UnknownFleet:
        pass
    rng = np.random.default_rng(1)
    edges = rng.choice(entry.network.n_edges, size=DEMO_VEHICLES, replace=False)
    vehicles = [
        VehicleSpec(
            id=f"v{i + 1:02d}",
            position=EdgePosition(edge=entry.network.edge_ids[int(e)], offset=0.0),
        )
        for i, e in enumerate(sorted(edges))
    ]
    spec = FleetSpec(
        id=DEMO_FLEET,
        network=entry.id,
        vehicles=vehicles,
        reference_demand=DEMO_DEMAND,
    )
    try:
        service.create_fleet(spec)
    except Conflict as exc:
        log.info("demo fleet not created: %s", exc)


async def feed_demo_targets(service: FleetService, rate: float) -> None:
    """Post targets drawn from the demo fleet's reference demand, ``rate`` per second."""
    rng = np.random.default_rng(2)
    while True:
        await asyncio.sleep(1.0 / rate)
        try:
            runtime = await run_in_threadpool(service._runtime, DEMO_FLEET)
            atom = runtime.reference_distribution().sample(rng, 1)[0]
            edge = runtime.entry.network.edge_ids[atom.edge]
            target = TargetSpec(position=EdgePosition(edge=edge, offset=atom.offset))
            await run_in_threadpool(service.post_targets, DEMO_FLEET, [target])
        except UnknownFleet:
            return
        except RoutingSvcError as exc:  # keep feeding; the demo must not stop on one target
            log.warning("demo target rejected: %s", exc)
