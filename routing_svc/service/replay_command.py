"""``routing-svc replay``: rebuild fleets from the event log and check them bit for bit."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from routing_svc.errors import InvalidInput, ReplayMismatch


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "replay",
        help="replay a fleet's event log and compare with the stored state",
    )
    p.add_argument("--db", type=Path, default=None, help="SQLite file")
    p.add_argument("--database-url", default=None)
    p.add_argument("--fleet", action="append", default=[], help="fleet id (default: all)")
    p.add_argument("--data-dir", type=Path, default=Path("var/networks"))
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from routing_svc.service.app import load_networks
    from routing_svc.service.fleets import FleetService
    from routing_svc.service.networks import NetworkRegistry
    from routing_svc.service.settings import Settings
    from routing_svc.store import EventLog

    if (args.db is None) == (args.database_url is None):
        raise InvalidInput("give exactly one of --db PATH or --database-url URL")
    if args.db is not None and not args.db.is_file():
        raise InvalidInput(f"no database file {str(args.db)!r}")
    url = args.database_url or f"sqlite:///{args.db.resolve()}"
    settings = Settings(database_url=url, data_dir=args.data_dir)
    with EventLog(url) as log:
        registry = NetworkRegistry(data_dir=args.data_dir, max_bytes=settings.max_network_bytes)
        load_networks(registry, log, settings)
        service = FleetService(log, registry, recent_window=settings.recent_window)
        ids = args.fleet or [f.id for f in log.list_fleets(include_deleted=True)]
        reports = []
        failed = False
        for fleet_id in ids:
            try:
                reports.append({"ok": True, **service.verify(fleet_id)})
            except ReplayMismatch as exc:
                failed = True
                reports.append({"ok": False, "fleet": fleet_id, "error": exc.detail})
    print(json.dumps({"fleets": reports, "ok": not failed}, indent=2))
    return 1 if failed else 0
