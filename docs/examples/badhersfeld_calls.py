"""Write a history of calls in Bad Hersfeld: ``time,lon,lat`` from its buildings.

A call comes from a building with probability proportional to its weight, at a uniform
point of the building's nearest road (``GenEdge``), on a day whose hourly rate follows a
simple profile (quiet at night). Used by the README's "Your own city" section::

    python docs/examples/badhersfeld_calls.py ../shared/nets calls.csv --calls 3000
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
from pathlib import Path

import numpy as np
import sumolib

from routing_svc.network import load_network

HOURLY = np.array([1, 1, 1, 1, 1, 2, 4, 6, 7, 7, 6, 6, 6, 6, 6, 7, 8, 8, 7, 5, 4, 3, 2, 1.0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("shared", type=Path, help="the folder with badhersfeld.* files")
    parser.add_argument("out", type=Path)
    parser.add_argument("--calls", type=int, default=3000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    net = sumolib.net.readNet(str(args.shared / "badhersfeld.net.xml.gz"))
    projection = load_network(args.shared / "badhersfeld.net.xml.gz").projection
    assert projection is not None, "the network has a geo-projection"
    with open(args.shared / "badhersfeld.buildings.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if net.hasEdge(r["GenEdge"])]
    weights = np.array([float(r["Weight"]) for r in rows])
    picks = rng.choice(len(rows), size=args.calls, p=weights / weights.sum())
    hours = rng.choice(24, size=args.calls, p=HOURLY / HOURLY.sum())
    seconds = np.sort(hours * 3600 + rng.uniform(0, 3600, size=args.calls))
    day = dt.datetime(2026, 3, 2, tzinfo=dt.UTC)
    with open(args.out, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["time", "lon", "lat"])
        for pick, second in zip(picks.tolist(), seconds.tolist(), strict=True):
            edge = net.getEdge(rows[pick]["GenEdge"])
            x, y = sumolib.geomhelper.positionAtShapeOffset(
                edge.getShape(), rng.uniform(0, edge.getLength())
            )
            lon, lat = projection.point_to_lonlat(x, y)
            when = day + dt.timedelta(seconds=second)
            writer.writerow([when.isoformat(timespec="seconds"), f"{lon:.6f}", f"{lat:.6f}"])


if __name__ == "__main__":
    main()
