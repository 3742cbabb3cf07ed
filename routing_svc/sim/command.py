"""``routing-svc cosim``: compare fleet policies in a SUMO co-simulation.

Examples::

    routing-svc cosim --net grid --vehicles 4 --duration 900 --seeds 0
    routing-svc cosim --net drt --vehicles 10 --hours 2 --seeds 0,1,2 --workers 2
    routing-svc cosim --net drt --mode incidents --traffic-costs 60
    routing-svc cosim --net drt --history 1000 --policies sa,sa-cold,optimum,sumo-stop
    routing-svc cosim --net drt --policies sa,sa-floor --shift-at 3600 --history 1000
    routing-svc cosim --net drt --service-url http://127.0.0.1:8000 --policies sa
    routing-svc cosim --net grid --gui --policies sa --seeds 0
    routing-svc cosim --net badhersfeld.net.xml.gz --stands badhersfeld.parking.add.xml

Prints the JSON summary (one entry per policy: SUMO's mean and 90th-percentile
wait, the fraction within 300/600/900 s, requests served, empty km, requests
per vehicle-hour, busy fraction, simulation speed) and the network's traffic
lights (``signals``: links the programs SUMO runs never turn green, with a
warning on standard error if there are any); writes it with the inputs,
SUMO's outputs and the PNG plots under ``--out``.

With ``--stands FILE.add.xml`` the usable ``parkingArea`` elements of the file
(read as ``routing-svc stands`` reads them) are the stands: the service's fleets
are restricted to them and their idle vehicles park in them, ``optimum`` is
the optimum over them and ``sumo-taxistand`` uses them as its taxi stands. The
summary's ``stands`` names the file and counts the stands; ``unparked`` counts
the vehicles that found no room in their stand.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from routing_svc.errors import InvalidInput
from routing_svc.json_text import json_text
from routing_svc.sim.dispatcher import QUEUE_ORDERS
from routing_svc.sim.measures import DEFAULT_THRESHOLDS
from routing_svc.sim.spec import DEFAULT_INCIDENT_SAMPLE

__all__ = ["add_parser", "parse_seeds", "run"]


def parse_seeds(text: str) -> tuple[int, ...]:
    """``--seeds`` (or any option of counts): a comma list of integers >= 0."""
    try:
        seeds = tuple(int(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected integers, got {text!r}") from None
    if not seeds or any(s < 0 for s in seeds):
        raise argparse.ArgumentTypeError("give at least one integer >= 0")
    return seeds


def add_parser(subparsers: Any) -> None:
    """Add ``cosim`` to the ``routing-svc`` command line."""
    p = subparsers.add_parser(
        "cosim",
        help="SUMO co-simulation: the service's dispatch and SA vs optimum and SUMO's own taxis",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--net", default="drt", help="network name or .net.xml path (default: drt)")
    p.add_argument("--mode", choices=["persons", "incidents"], default="persons")
    p.add_argument("--vehicles", type=int, default=10)
    p.add_argument("--hours", type=float, default=None, help="request period in hours")
    p.add_argument("--duration", type=float, default=7200.0, help="request period (s)")
    p.add_argument("--warmup", type=float, default=600.0, help="traffic before requests (s)")
    p.add_argument("--drain", type=float, default=900.0, help="simulated after requests (s)")
    p.add_argument("--rate", type=float, default=60.0, help="requests per hour")
    p.add_argument(
        "--demand",
        default="hotspots:3",
        help="uniform | hotspots[:K] | weights:FILE | buildings:FILE, optionally "
        "?profile=FILE (24 hourly rate weights); see routing_svc.demand.spec",
    )
    p.add_argument("--demand-seed", type=int, default=1, help="seed of the hotspot layout")
    p.add_argument("--shift-at", type=float, default=None, help="hotspots move after S seconds")
    p.add_argument("--density", type=float, default=10.0, help="background vehicles/h/km")
    p.add_argument(
        "--traffic-costs",
        type=float,
        default=None,
        metavar="N",
        help="push SUMO's edge travel times to the fleet every N seconds",
    )
    p.add_argument("--cost", choices=["time", "length"], default="time")
    p.add_argument(
        "--rule",
        choices=["consolidating", "probe", "paper"],
        default=None,
        help="learning rule of the service's fleets (default: the service's)",
    )
    p.add_argument(
        "--policies",
        default=None,
        help="comma list (default: sa,sa-available,optimum,sumo-stop,sumo-taxistand; "
        "also sa-cold, sa-floor, static, sumo-closest, sumo-circling)",
    )
    p.add_argument(
        "--stands",
        type=Path,
        default=None,
        metavar="FILE.add.xml",
        help="park at the usable parkingAreas of a SUMO additional file (stands)",
    )
    p.add_argument(
        "--move-up",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="idle vehicles wait at the service's posts (GET .../posts, default), or at their "
        "own references (--no-move-up)",
    )
    p.add_argument(
        "--queue",
        choices=QUEUE_ORDERS,
        default="soonest",
        help="which waiting request the service's vehicles serve next: the one they reach "
        f"soonest, overdue ones (past {max(DEFAULT_THRESHOLDS):g} s) first (default), "
        "or the oldest (fifo)",
    )
    p.add_argument("--seeds", type=parse_seeds, default=(0,), help="comma list of seeds")
    p.add_argument("--workers", type=int, default=2, help="parallel SUMO processes")
    p.add_argument("--service-url", default=None, help="a running service (default: in-process)")
    p.add_argument("--backend", choices=["libsumo", "traci"], default="libsumo")
    p.add_argument("--gui", action="store_true", help="watch in sumo-gui (TraCI)")
    p.add_argument("--out", type=Path, default=Path("cosim-out"), help="output folder")
    p.add_argument(
        "--resume", action="store_true", help="reuse the runs saved in --out for the same options"
    )
    p.add_argument("--history", type=int, default=0, help="historical requests sa learns first")
    p.add_argument(
        "--incident-sample",
        type=int,
        default=DEFAULT_INCIDENT_SAMPLE,
        help="incidents: incidents recorded apart whose p-median is the optimum "
        f"(default {DEFAULT_INCIDENT_SAMPLE})",
    )
    p.add_argument("--ride-radius", type=float, default=1500.0, help="rides end within R metres")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the co-simulation the arguments describe; print its JSON summary."""
    from routing_svc.sim.experiment import CosimSpec, run_cosim
    from routing_svc.sim.policies import parse_policies

    duration = args.hours * 3600.0 if args.hours is not None else args.duration
    if args.vehicles < 1 or args.workers < 1:
        raise InvalidInput("--vehicles and --workers must be >= 1")
    spec = CosimSpec(
        network=args.net,
        mode=args.mode,
        vehicles=args.vehicles,
        duration=duration,
        warmup=args.warmup,
        drain=args.drain,
        rate=args.rate,
        demand=args.demand,
        demand_seed=args.demand_seed,
        shift_at=args.shift_at,
        ride_radius=args.ride_radius,
        history=args.history,
        incident_sample=args.incident_sample,
        density=args.density,
        traffic_period=args.traffic_costs,
        cost=args.cost,
        policies=parse_policies(args.policies),
        seeds=args.seeds,
        service_url=args.service_url,
        backend=args.backend,
        gui=args.gui,
        workers=args.workers,
        rule=args.rule,
        stands=None if args.stands is None else str(args.stands),
        move_up=args.move_up,
        queue_order=args.queue,
    )
    result = run_cosim(spec, out_dir=args.out, progress=not args.quiet, resume=args.resume)
    if not args.no_plots:
        from routing_svc.sim.plots import write_figures

        write_figures(result, out_dir=args.out, prefix="cosim")
    summary = result.summary()
    print(json_text({"out": str(args.out), **summary}, indent=2))
    return 0
