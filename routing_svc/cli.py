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

COMMANDS: dict[str, str] = {
    "serve": "routing_svc.service.command",
    "replay": "routing_svc.service.replay_command",
    "nets": "routing_svc.nets",
    "optimum": "routing_svc.optimum.command",
    "simulate": "routing_svc.simulate",
    "cosim": "routing_svc.sim.command",
    "paper": "routing_svc.paper.command",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="routing-svc",
        description="Keeps a vehicle fleet where it is needed: stochastic-approximation "
        "deployment on SUMO road networks.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module_name in COMMANDS.values():
        module = importlib.import_module(module_name)
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``routing-svc``."""
    parser = build_parser()
    args = parser.parse_args(argv)
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
