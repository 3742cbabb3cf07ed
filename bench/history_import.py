"""Bulk speed of ``routing-svc history import`` (in process) against the batch route
posted 50 targets at a time.

A history of ``--calls`` calls at the buildings of Bad Hersfeld (edges of
``badhersfeld.buildings.csv``, weighted by building, a random offset) is written
to CSV and imported in process into a 50-vehicle fleet (reading, checking,
sorting, keyed chunks of ``--chunk-size``), consolidations solved in
``--consolidation-workers`` processes as the command does. The baseline, in the
same run, posts the same calls, already resolved, in time order through the same
domain call of ``POST /v1/fleets/{id}/targets:batch`` at 50 targets per request
into a twin fleet. Both fleets start at the p-median of the same history; each
fleet's log is then replayed and checked bit for bit.

Usage::

    python bench/history_import.py [--calls 1000000] [--chunk-size 2000]
        [--consolidation-workers 1]

Prints one JSON document: calls/s and seconds of each, and their ratio.
"""

from __future__ import annotations

import argparse
import csv
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_shared import SHARED

from routing_svc.history import (
    InProcessHistoryClient,
    history_fleet_spec,
    place_locally,
    read_calls,
    replay_history,
)
from routing_svc.history.command import SERVER_CONSOLIDATION_WORKERS
from routing_svc.long_lived import frozen_heap

BASELINE_BATCH = 50


def write_history(path: Path, n: int, *, lengths: dict[str, float], seed: int) -> None:
    with (SHARED / "badhersfeld.buildings.csv").open() as f:
        rows = [(r["GenEdge"], float(r["Weight"])) for r in csv.DictReader(f)]
    rows = [(e, w) for e, w in rows if e in lengths]
    weights = np.array([w for _, w in rows])
    rng = np.random.default_rng(seed)
    picked = rng.choice(len(rows), size=n, p=weights / weights.sum())
    fractions = rng.uniform(0.0, 1.0, size=n)
    times = np.sort(rng.uniform(0.0, 365 * 86_400.0, size=n))
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["time", "edge", "offset"])
        for t, i, u in zip(times.tolist(), picked.tolist(), fractions.tolist(), strict=True):
            edge = rows[i][0]
            writer.writerow([round(t, 1), edge, round(u * lengths[edge], 2)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=1_000_000)
    parser.add_argument("--vehicles", type=int, default=50)
    parser.add_argument("--chunk-size", type=int, default=2_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--consolidation-workers", type=int, default=SERVER_CONSOLIDATION_WORKERS)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="history_bench_") as tmp:
        folder = Path(tmp)
        with InProcessHistoryClient(
            database_url=f"sqlite:///{folder / 'e.db'}",
            consolidation_workers=args.consolidation_workers,
        ) as client:
            client.add_network(SHARED / "badhersfeld.net.xml.gz", name="bh")
            entry = client.service.network("bh")
            net = entry.network
            lengths = {e: float(net.length[i]) for i, e in enumerate(net.edge_ids)}
            path = folder / "calls.csv"
            write_history(path, args.calls, lengths=lengths, seed=args.seed)
            table = read_calls(path)
            placed = place_locally(table, entry, vehicle_types=None)
            for fleet in ("import", "baseline"):
                client.create_fleet(
                    history_fleet_spec(
                        table, placed, fleet_id=fleet, network="bh", vehicles=args.vehicles
                    )
                )

            started = time.perf_counter()
            table = read_calls(path)
            placed = place_locally(table, entry, vehicle_types=["default"] * args.vehicles)
            result = replay_history(
                table, placed, client, "import", chunk_size=args.chunk_size, progress=False
            )
            imported = time.perf_counter() - started

            bodies = [
                {"position": {"edge": e, "offset": o}}
                for e, o in zip(placed.edges, placed.offsets, strict=True)
            ]
            started = time.perf_counter()
            with frozen_heap():  # as the server's is, and the import's
                for k in range(0, len(bodies), BASELINE_BATCH):
                    client.post_batch(
                        "baseline", bodies[k : k + BASELINE_BATCH], idempotency_key=f"b{k}"
                    )
            baseline = time.perf_counter() - started
            same = (
                client.get_fleet("import")["vehicles"] == client.get_fleet("baseline")["vehicles"]
            )
            replayed = all(
                client.service.verify(fleet)["snapshot_identical"] is True
                for fleet in ("import", "baseline")
            )
    print(
        json.dumps(
            {
                "calls": args.calls,
                "vehicles": args.vehicles,
                "network": "badhersfeld",
                "chunk_size": args.chunk_size,
                "import": {
                    "seconds": imported,
                    "calls_per_second": args.calls / imported,
                    "sending_seconds": result.seconds,
                },
                "baseline_batch_50": {
                    "seconds": baseline,
                    "calls_per_second": args.calls / baseline,
                },
                "speed_ratio_import_over_baseline": baseline / imported,
                "consolidation_workers": args.consolidation_workers,
                "same_final_positions": same,
                "replays_bit_for_bit": replayed,
                "goal": "1,000,000 calls in under 60 s",
                "extrapolated_seconds_for_1m": imported * 1_000_000 / args.calls,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
