"""``routing-svc import-osm``: an OpenStreetMap extract into a SUMO network.

::

    routing-svc import-osm FILE.osm[.xml][.gz] -o NET.net.xml.gz [--cars-only]
        [--max-bytes N] [--json]

screens the extract as hostile XML, runs SUMO's ``netconvert`` with SUMO's
recommended OpenStreetMap options (:mod:`routing_svc.network.osm_import`) and
prints what came out: junctions, edges, edges open to cars, the largest
strongly connected car component (what a fleet uses) and netconvert's
warnings by kind. A file that is not OpenStreetMap, hostile or too large ends
with a one-line error and exit code 2.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from routing_svc.network.osm_import import DEFAULT_MAX_OSM_BYTES, import_osm


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``import-osm`` command."""
    parser = subparsers.add_parser(
        "import-osm",
        help="convert an OpenStreetMap extract into a SUMO network (netconvert)",
        description="Convert an OpenStreetMap extract (.osm, .osm.xml, optionally gzipped) "
        "into a gzipped SUMO network with SUMO's recommended netconvert options and "
        "typemaps, and report what a fleet can use of it.",
    )
    parser.add_argument("source", type=Path, metavar="FILE", help="the .osm[.xml][.gz] extract")
    parser.add_argument(
        "-o", "--output", required=True, type=Path, metavar="NET", help="the .net.xml.gz to write"
    )
    parser.add_argument(
        "--cars-only",
        action="store_true",
        help="keep only roads open to passenger cars (default: every road class, so that "
        "persons can walk in a co-simulation)",
    )
    parser.add_argument(
        "--max-bytes",
        type=int,
        default=DEFAULT_MAX_OSM_BYTES,
        metavar="N",
        help=f"largest decompressed extract accepted (default {DEFAULT_MAX_OSM_BYTES})",
    )
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Import and print the summary; return the exit status."""
    summary = import_osm(
        args.source, args.output, max_bytes=args.max_bytes, cars_only=args.cars_only
    )
    if args.json:
        print(json.dumps(summary.to_dict(), indent=2))
    else:
        print("\n".join(summary.lines()))
    return 0
