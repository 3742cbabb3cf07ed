"""Generate the small SUMO networks of routing_svc (deterministically).

Usage::

    python sumo_nets/generate.py [--out DIR] [--name NAME ...] [--force]

Without ``--out`` the files go to the cache folder that the service uses
(``$ROUTING_SVC_CACHE/nets``, else ``~/.cache/routing_svc/nets``). The recipes
live in :mod:`routing_svc.network.catalogue`, so the installed package can make the same
files on demand without this script.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from routing_svc.network.catalogue import GENERATED, cache_dir, generate_network


def main(argv: list[str] | None = None) -> int:
    """Generate the requested networks and print their paths."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help=f"folder (default {cache_dir()})")
    parser.add_argument(
        "--name",
        action="append",
        choices=sorted(GENERATED),
        help="network to generate (repeatable; default: all)",
    )
    parser.add_argument("--force", action="store_true", help="regenerate existing files")
    args = parser.parse_args(argv)
    for name in args.name or list(GENERATED):
        path = generate_network(name, out_dir=args.out, force=args.force)
        print(f"{name}\t{path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
