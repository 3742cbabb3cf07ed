"""``routing-svc stands``: the stands of a SUMO additional file that a network can use.

::

    routing-svc stands FILE.add.xml --net NET [--json]

reads the file's ``parkingArea`` elements (:mod:`routing_svc.network.stands`),
and prints the usable stands (edge, offset, capacity) and the dropped ones with
their reasons. With ``--json`` the usable stands are the list a fleet spec's
``stands`` field takes. A file that is not an additional file ends with a
one-line error and exit code 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from routing_svc.json_text import json_text
from routing_svc.network.cache import load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.network.stands import read_stands_file


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``stands`` command."""
    parser = subparsers.add_parser(
        "stands",
        help="the usable stands (SUMO parkingAreas) of an additional file on a network",
        description="Read the parkingArea elements of a SUMO additional file as stands "
        "(edge, offset at the middle, capacity) and print those the network can use, and "
        "the dropped ones with the reason.",
    )
    parser.add_argument("source", type=Path, metavar="FILE", help="a SUMO additional file")
    parser.add_argument("--net", required=True, metavar="PATH", help="a .net.xml[.gz] or a name")
    parser.add_argument(
        "--json",
        action="store_true",
        help="print JSON: 'stands' (the list a fleet spec's 'stands' field takes) and 'dropped'",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Read the stands and print them; return the exit status."""
    network = load_network(resolve_network(args.net))
    reading = read_stands_file(args.source, network)
    if args.json:
        report = {
            "stands": [s.to_dict() for s in reading.usable],
            "dropped": [{"id": d.id, "edge": d.edge, "reason": d.reason} for d in reading.dropped],
        }
        print(json_text(report, indent=2))
        return 0
    print(
        f"{len(reading.usable)} usable stands (capacity {reading.capacity}), "
        f"{len(reading.dropped)} dropped"
    )
    for stand in reading.usable:
        print(
            f"  {stand.id}: edge {stand.edge} offset {stand.offset:.2f} capacity {stand.capacity}"
        )
    for dropped in reading.dropped:
        print(f"  dropped {dropped.id} (edge {dropped.edge}): {dropped.reason}")
    return 0
