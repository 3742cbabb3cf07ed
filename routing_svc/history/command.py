"""``routing-svc history``: import a history of calls into a fleet, or create a fleet
from one.

::

    routing-svc history import CALLS.csv --fleet ID [--db PATH | --database-url URL |
        --service-url URL [--net PATH]] [--on-bad-row refuse|skip] [--chunk-size N]
        [--report DIR] [--thresholds 300,600,900] [--consolidation-workers N]
    routing-svc history create-fleet CALLS.csv --net NET --vehicles N|TYPE:N,... --fleet ID [...]

In process (the default) the service's domain code runs on the database that
``serve`` uses (``--db``/``--database-url``, default ``var/routing_svc.db``); with
``--service-url`` a running server does the work. The import prints a JSON
summary on stdout; bad rows are listed there (``skip``) or in the error
(``refuse``, exit code 2, nothing sent).
"""

from __future__ import annotations

import argparse
import os
from contextlib import ExitStack
from pathlib import Path
from typing import Any, cast

from routing_svc.errors import InvalidInput
from routing_svc.history.calls import read_calls
from routing_svc.history.creation import (
    history_fleet_spec,
    history_vehicle_types,
    parse_vehicle_mix,
)
from routing_svc.history.places import (
    PlacedCalls,
    place_locally,
    place_on_network,
    place_remotely,
)
from routing_svc.history.replay import (
    DEFAULT_CHUNK,
    HistoryClient,
    HttpHistoryClient,
    InProcessHistoryClient,
    replay_history,
)
from routing_svc.history.report import DEFAULT_THRESHOLDS, write_report
from routing_svc.json_text import json_text
from routing_svc.service.command import database_url_of
from routing_svc.service.networks import NetworkEntry, NetworkRegistry
from routing_svc.service.settings import Settings
from routing_svc.types import NetPosition


def _thresholds(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--thresholds takes numbers like 300,600, got {text!r}"
        ) from None
    if not values or any(not v > 0 for v in values):
        raise argparse.ArgumentTypeError("thresholds must be positive numbers")
    return values


SERVER_CONSOLIDATION_WORKERS: int = Settings.model_fields["consolidation_workers"].default
"""The server's default, which an in-process import keeps."""


def _where(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "calls", type=Path, metavar="CALLS.csv", help="the history (see docs/history.md)"
    )
    p.add_argument("--fleet", required=True, help="the fleet's id")
    p.add_argument("--db", type=Path, default=None, help="SQLite file (default var/routing_svc.db)")
    p.add_argument("--database-url", default=None, help="SQLAlchemy URL of the event log")
    p.add_argument("--service-url", default=None, help="a running server instead of in-process")
    p.add_argument("--api-key", default=os.environ.get("ROUTING_SVC_API_KEY"))
    p.add_argument(
        "--on-bad-row",
        choices=["refuse", "skip"],
        default="refuse",
        help="refuse (default): import nothing if a row is bad; skip: list and leave them out",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def add_parser(sub: Any) -> None:
    history = sub.add_parser("history", help="import a history of calls; report service levels")
    commands = history.add_subparsers(dest="history_command", required=True, metavar="COMMAND")
    p = commands.add_parser("import", help="replay a history's calls, in time order, into a fleet")
    _where(p)
    p.add_argument(
        "--chunk-size",
        type=int,
        default=DEFAULT_CHUNK,
        help=f"targets per request (default {DEFAULT_CHUNK})",
    )
    p.add_argument(
        "--report", type=Path, default=None, metavar="DIR", help="write report.json and plots here"
    )
    p.add_argument(
        "--thresholds",
        type=_thresholds,
        default=DEFAULT_THRESHOLDS,
        help="service-level thresholds in cost units (default 300,600,900)",
    )
    p.add_argument("--net", default=None, help="with --service-url and --report: the network file")
    p.add_argument(
        "--consolidation-workers",
        type=int,
        default=SERVER_CONSOLIDATION_WORKERS,
        help="in process: processes that solve consolidations off the write path, as the "
        f"server's (default {SERVER_CONSOLIDATION_WORKERS}); 0 solves each inside its "
        "target, the same run on any machine",
    )
    p.set_defaults(run=run_import)
    c = commands.add_parser("create-fleet", help="create a fleet at the p-median of a history")
    _where(c)
    c.add_argument("--net", required=True, help="network id, or NAME=PATH to register a file")
    c.add_argument(
        "--vehicles",
        required=True,
        help="how many identical vehicles (8), or of each type (A:5,B:3): each type "
        "starts at the optimum of the calls that needed it and of those for any one",
    )
    c.add_argument("--cost", choices=["length", "time"], default="length")
    c.add_argument("--seed", type=int, default=0)
    c.set_defaults(run=run_create)


def _client(args: argparse.Namespace) -> HistoryClient:
    if args.service_url:
        if args.db or args.database_url:
            raise InvalidInput("give --service-url or a database, not both")
        return HttpHistoryClient(args.service_url, api_key=args.api_key)
    workers = getattr(args, "consolidation_workers", 0)
    if workers < 0:
        raise InvalidInput(f"--consolidation-workers must be >= 0, got {workers}")
    return InProcessHistoryClient(
        database_url=database_url_of(args.db, args.database_url),
        consolidation_workers=workers,
    )


def _entry(client: HistoryClient, network_id: str, net: str | None) -> NetworkEntry:
    """The fleet's network: the service's own in process, else loaded from ``net``."""
    if isinstance(client, InProcessHistoryClient):
        return client.service.network(network_id)
    if net is None:
        raise InvalidInput(
            "with --service-url, --report needs --net PATH (the fleet's network file)"
        )
    from routing_svc.network.catalogue import resolve_network

    registry = NetworkRegistry(data_dir=Path("."), max_bytes=1 << 30)
    return registry.load(network_id, resolve_network(net))


def _place(
    args: argparse.Namespace, client: HistoryClient, table: Any, fleet: dict[str, Any]
) -> PlacedCalls:
    if isinstance(client, InProcessHistoryClient):
        entry = client.service.network(fleet["network"])
        return place_locally(table, entry, vehicle_types=[v["type"] for v in fleet["vehicles"]])
    return place_remotely(table, client, args.fleet, progress=not args.quiet)


def run_import(args: argparse.Namespace) -> int:
    table = read_calls(args.calls)
    with ExitStack() as stack:
        client = _client(args)
        stack.callback(client.close)
        fleet = client.get_fleet(args.fleet)
        placed = _place(args, client, table, fleet)
        result = replay_history(
            table,
            placed,
            client,
            args.fleet,
            on_bad_row=args.on_bad_row,
            chunk_size=args.chunk_size,
            progress=not args.quiet,
        )
        summary = result.summary()
        if args.report is not None:
            entry = _entry(client, fleet["network"], args.net)
            index = {int(r): i for i, r in enumerate(placed.rows.tolist())}
            targets = [
                NetPosition(
                    entry.network.edge_index[placed.edges[index[r]]], placed.offsets[index[r]]
                )
                for r in result.order.tolist()
            ]
            report = write_report(
                args.report,
                entry,
                fleet=fleet,
                summary=summary,
                targets=targets,
                costs=result.costs,
                hours=table.hours[result.order],
                checkpoints=result.checkpoints,
                thresholds=args.thresholds,
            )
            summary["report"] = str(args.report)
            summary["gap_end"] = report["gap"]["curve"][-1]["gap"]
            summary["service_levels"] = report["service_levels"]["all"]
    print(json_text(summary, indent=2))
    return 0


def run_create(args: argparse.Namespace) -> int:
    vehicles = parse_vehicle_mix(args.vehicles)
    table = read_calls(args.calls)
    name, sep, path = args.net.partition("=")
    with ExitStack() as stack:
        client = _client(args)
        stack.callback(client.close)
        placed: PlacedCalls | None = None
        if sep:
            from routing_svc.network.catalogue import resolve_network

            client.add_network(resolve_network(path), name=name)
        types = history_vehicle_types(vehicles)  # the calls the new fleet can serve
        if isinstance(client, HttpHistoryClient):
            placed = place_on_network(
                table, client, name, vehicle_types=types, progress=not args.quiet
            )
        else:
            entry = cast(InProcessHistoryClient, client).service.network(name)
            placed = place_locally(table, entry, vehicle_types=types)
        bad = placed.bad
        if bad and args.on_bad_row == "refuse":
            from routing_svc.history.replay import HistoryRefused

            raise HistoryRefused(bad)
        spec = history_fleet_spec(
            table, placed, fleet_id=args.fleet, network=name, vehicles=vehicles,
            cost=args.cost, seed=args.seed,
        )  # fmt: skip
        fleet = client.create_fleet(spec)
    out = {
        "fleet": fleet["id"],
        "network": fleet["network"],
        "sample": len(spec["start"]["optimum"]["sample"]),
        "bad_rows": [r.to_dict() for r in bad],
        "vehicles": [
            {"id": v["id"], "edge": v["position"]["edge"], "offset": v["position"]["offset"]}
            for v in fleet["vehicles"]
        ],
    }
    print(json_text(out, indent=2))
    return 0
