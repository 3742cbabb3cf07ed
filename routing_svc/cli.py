"""The ``routing-svc`` command line.

Each subcommand lives in the module of its layer, which exposes
``add_parser(subparsers)`` and ``run(args) -> int``; this file only wires them.
Bad input ends with a one-line error on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from routing_svc.errors import RoutingSvcError

COMMANDS: dict[str, tuple[str, str]] = {
    "serve": ("routing_svc.service.command", "run the REST service with the dashboard"),
    "replay": ("routing_svc.service.replay_command", "replay event logs, check bit for bit"),
    "nets": ("routing_svc.network.catalogue", "list the generated and the eclipse-sumo networks"),
    "import-osm": ("routing_svc.network.osm_command", "OpenStreetMap extract -> SUMO network"),
    "stands": ("routing_svc.network.stands_command", "the usable stands of a SUMO additional file"),
    "optimum": ("routing_svc.optimum.command", "exact / best-known p-median as JSON"),
    "simulate": ("routing_svc.offline_run", "offline SA run with the gap to the optimum"),
    "cosim": ("routing_svc.sim.command", "SUMO co-simulation of the fleet in traffic"),
    "paper": ("routing_svc.paper.command", "the paper's other scenarios as experiments"),
    "history": ("routing_svc.history.command", "import a history of calls; report service levels"),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser; only ``command``'s module is imported (all of them when ``None``)."""
    parser = argparse.ArgumentParser(
        prog="routing-svc",
        description="Keeps a vehicle fleet where it is needed: stochastic-approximation "
        "deployment on SUMO road networks.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (module_name, summary) in COMMANDS.items():
        if command is None or name == command:
            importlib.import_module(module_name).add_parser(sub)
        else:
            sub.add_parser(name, help=summary)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``routing-svc``."""
    words = list(sys.argv[1:] if argv is None else argv)
    chosen = next((w for w in words if w in COMMANDS), None)
    parser = build_parser(chosen)
    args = parser.parse_args(words)
    try:
        code: int = args.run(args)
    except RoutingSvcError as exc:
        print(f"routing-svc {args.command}: {exc.title.lower()}: {exc.detail}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    return code


if __name__ == "__main__":
    sys.exit(main())
