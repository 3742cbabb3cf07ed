"""``routing-svc optimum``: the p-median of a demand distribution on a road network.

::

    routing-svc optimum --net PATH --vehicles P [--demand SPEC]
        [--cost length|time] [--seed S] [--method auto|milp|heuristic]
        [--max-sites N] [--time-limit SECONDS] [--stands FILE.add.xml]

prints one JSON object: the expected cost of the best configuration found
(``objective``, in metres or seconds), the vehicle positions (SUMO edge id,
offset, x, y), how it was found (``method``, ``proven_optimal``,
``lower_bound``, ``seconds``) and the problem size (``n_sites`` offered after
subsampling and merging identical rows, ``candidate_sites`` before, ``n_demand``).
Without ``--max-sites`` every candidate site is offered; never more than a cost matrix
of :data:`~routing_svc.optimum.solve.MATRIX_BYTES` holds (evenly subsampled beyond).
With ``--stands`` the vehicles park at the usable stands of a SUMO
additional file (read as ``routing-svc stands`` reads it), within their
capacities (:func:`~routing_svc.optimum.stands.solve_stands`; one position per
vehicle, repeated at a stand that holds several); the report adds the stands
read (``stands``), the optimum without them (``free_objective``) and
``ratio`` = ``objective / free_objective``. Bad input raises
:class:`~routing_svc.errors.RoutingSvcError`, which ``routing_svc.cli`` turns into a
one-line message and exit code 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from routing_svc.demand.spec import network_demand, parse_demand_spec
from routing_svc.errors import InvalidInput
from routing_svc.json_text import json_text
from routing_svc.network import CompiledNetwork, RoadSpace, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.network.costs import CostKind
from routing_svc.network.stands import usable_stands
from routing_svc.optimum.candidates import candidate_sites
from routing_svc.optimum.evaluate import expected_cost
from routing_svc.optimum.pmedian import Method
from routing_svc.optimum.solve import DemandOptimum, solve_demand
from routing_svc.optimum.stands import solve_stands
from routing_svc.types import NetPosition

_UNITS = {"length": "m", "time": "s"}
_COSTS: dict[str, CostKind] = {"length": "length", "time": "time"}
_METHODS: dict[str, Method] = {"auto": "auto", "milp": "milp", "heuristic": "heuristic"}


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``optimum`` command."""
    parser = subparsers.add_parser(
        "optimum",
        help="exact / best-known p-median of a demand distribution, as JSON",
        description="Place P vehicles to minimise the expected travel cost to a demand "
        "distribution on a SUMO network (a network p-median); print JSON.",
    )
    parser.add_argument("--net", required=True, metavar="PATH", help="a .net.xml[.gz] or a name")
    parser.add_argument("--vehicles", required=True, type=int, metavar="P", help="fleet size")
    parser.add_argument(
        "--demand",
        default="uniform",
        metavar="SPEC",
        help="'uniform' (by road length), 'hotspots[:K]' (K Gaussian hotspots, default 3), "
        "'weights:FILE' (a CSV/JSON file of edge_id -> weight; a bare FILE too) or "
        "'buildings:FILE' (a buildings CSV with Weight and GenEdge columns)",
    )
    parser.add_argument("--cost", choices=tuple(_UNITS), default="length")
    parser.add_argument("--seed", type=int, default=0, help="seed for the hotspot centres")
    parser.add_argument("--method", choices=tuple(_METHODS), default="auto")
    parser.add_argument(
        "--max-sites",
        type=int,
        default=None,
        metavar="N",
        help="subsample the candidate sites (default: every one; never more than a cost "
        "matrix of 2 GiB holds; the heuristic also keeps it transposed, twice that at the peak)",
    )
    parser.add_argument(
        "--time-limit", type=float, default=60.0, metavar="SECONDS", help="for the exact method"
    )
    parser.add_argument(
        "--stands",
        type=Path,
        default=None,
        metavar="FILE",
        help="park at the usable stands (parkingAreas) of a SUMO additional file, within "
        "their capacities; adds the free optimum's objective and the ratio stands/free",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Solve and print the JSON report; return the exit status."""
    report = optimum_report(
        net=args.net,
        vehicles=args.vehicles,
        demand=args.demand,
        cost=args.cost,
        seed=args.seed,
        method=args.method,
        max_sites=args.max_sites,
        time_limit=args.time_limit,
        stands=args.stands,
    )
    print(json_text(report, indent=2))
    return 0


def optimum_report(
    *,
    net: str,
    vehicles: int,
    demand: str = "uniform",
    cost: str = "length",
    seed: int = 0,
    method: str = "auto",
    max_sites: int | None = None,
    time_limit: float = 60.0,
    stands: Path | None = None,
) -> dict[str, Any]:
    """Build the network, demand and candidate sites, solve, and report.

    Parameters
    ----------
    net : str
        Network file (or a name known to ``routing_svc.network.catalogue``).
    vehicles : int
        ``p``, the number of vehicles (``>= 1``).
    demand : str
        A demand spec (:func:`routing_svc.demand.spec.parse_demand_spec`).
    cost : {"length", "time"}
        Edge cost: metres or free-flow seconds.
    seed : int
        Seeds the hotspot centres.
    method : {"auto", "milp", "heuristic"}
        See :func:`~routing_svc.optimum.pmedian.solve_pmedian`.
    max_sites : int, optional
        Subsample the candidate sites to at most this many (default: every one); never
        more than :func:`~routing_svc.optimum.solve.sites_that_fit` the demand.
    time_limit : float
        Seconds for the exact method.
    stands : Path, optional
        A SUMO additional file whose usable ``parkingArea`` elements
        (:func:`~routing_svc.network.stands.read_stands_file`) are the only places
        vehicles may park.

    Returns
    -------
    dict
        The JSON-ready report.

    Raises
    ------
    RoutingSvcError
        Any bad input (missing file, ``vehicles < 1`` or above the number of
        sites, a bad demand spec, a stands file without a usable stand or with
        too little capacity for the fleet, ...).
    """
    if vehicles < 1:
        raise InvalidInput(f"--vehicles must be >= 1, got {vehicles}")
    if max_sites is not None and max_sites < 1:
        raise InvalidInput(f"--max-sites must be >= 1, got {max_sites}")
    if cost not in _UNITS:
        raise InvalidInput(f"--cost must be 'length' or 'time', got {cost!r}")
    if method not in _METHODS:
        raise InvalidInput(f"--method must be 'auto', 'milp' or 'heuristic', got {method!r}")
    path = resolve_network(net)
    network = load_network(path)
    recipe = parse_demand_spec(demand)
    distribution = network_demand(network, recipe, rng=np.random.default_rng(seed))
    reading = None if stands is None else usable_stands(stands, network, vehicles)
    space = RoadSpace(network, cost=_COSTS[cost])
    offered = len(candidate_sites(network, distribution))
    free = solve_demand(
        space,
        distribution,
        vehicles,
        max_sites=max_sites,
        distinct=True,
        method=_METHODS[method],
        time_limit=time_limit,
    )
    best: DemandOptimum[NetPosition] = free
    if reading is not None:
        best = solve_stands(
            space,
            distribution,
            vehicles,
            reading.stand_set(network),
            method=_METHODS[method],
            time_limit=time_limit,
        )
    solution = best.solution
    value = expected_cost(space, best.positions, np.ones(len(best.positions)), distribution)
    report = {
        "network": Path(path).name,
        "demand": distribution.name,
        "cost": cost,
        "unit": _UNITS[cost],
        "vehicles": vehicles,
        "objective": value,
        "lower_bound": solution.lower_bound,
        "positions": [_describe(space, network, p) for p in best.positions],
        "method": solution.method,
        "proven_optimal": solution.proven_optimal,
        "seconds": solution.seconds,
        "n_sites": len(best.sites),
        "candidate_sites": offered,
        "n_demand": len(distribution),
        "seed": seed,
    }
    if reading is not None:
        assert stands is not None
        unbounded = expected_cost(space, free.positions, np.ones(len(free.positions)), distribution)
        report |= {
            "stands": {
                "file": stands.name,
                "usable": len(reading.usable),
                "dropped": len(reading.dropped),
                "capacity": reading.capacity,
            },
            "free_objective": unbounded,
            "ratio": value / unbounded if unbounded > 0.0 else None,
        }
    return report


def _describe(space: RoadSpace, network: CompiledNetwork, position: NetPosition) -> dict[str, Any]:
    x, y = space.xy(position)
    return {
        "edge": network.edge_ids[position.edge],
        "offset": position.offset,
        "x": x,
        "y": y,
    }
