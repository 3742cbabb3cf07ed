"""A few hundred calls at Bad Hersfeld's buildings: a fleet at their p-median, the import
and its report."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from routing_svc.history import (
    InProcessHistoryClient,
    history_fleet_spec,
    place_locally,
    read_calls,
    replay_history,
)
from routing_svc.history.report import write_report
from routing_svc.types import NetPosition
from tests.history.conftest import write_csv

NETS = Path(__file__).resolve().parents[2].parent / "shared" / "nets"


def test_calls_at_the_buildings_of_bad_hersfeld(tmp_path: Path) -> None:
    with (NETS / "badhersfeld.buildings.csv").open() as f:
        edges = [row["GenEdge"] for row in csv.DictReader(f)]
    rng = np.random.default_rng(7)
    picked = rng.choice(len(edges), size=300)
    times = rng.uniform(0, 7 * 86_400, size=300)
    path = write_csv(
        tmp_path / "calls.csv",
        ["time", "edge", "offset"],
        [[t, edges[i], 0.0] for t, i in zip(times, picked, strict=True)],
    )
    with InProcessHistoryClient(database_url=f"sqlite:///{tmp_path / 'e.db'}") as client:
        client.add_network(NETS / "badhersfeld.net.xml.gz", name="bh")
        entry = client.service.network("bh")
        table = read_calls(path)
        placed = place_locally(table, entry, vehicle_types=None)
        # every building's edge is a usable edge of the network, or named as a bad row
        assert len(placed.edges) + len(placed.bad) == 300
        assert len(placed.edges) >= 250
        spec = history_fleet_spec(table, placed, fleet_id="bh", network="bh", vehicles=5)
        created = client.create_fleet(spec)
        assert len(created["vehicles"]) == 5
        result = replay_history(
            table, placed, client, "bh", on_bad_row="skip", chunk_size=64, progress=False
        )
        assert result.applied == len(placed.edges)
        assert client.get_fleet("bh")["version"] == 1 + len(placed.edges)
        index = {r: i for i, r in enumerate(placed.rows.tolist())}
        targets = [
            NetPosition(entry.network.edge_index[placed.edges[index[r]]], 0.0)
            for r in result.order.tolist()
        ]
        report = write_report(
            tmp_path / "report", entry, fleet=created, summary=result.summary(),
            targets=targets, costs=result.costs, hours=table.hours[result.order],
            checkpoints=result.checkpoints,
        )  # fmt: skip
    curve = report["gap"]["curve"]
    # the fleet starts at the p-median of these very calls: no gap at the start
    assert abs(curve[0]["gap"]) < 1e-9
    assert all(c["gap"] >= -1e-9 for c in curve)
    assert sum(h["calls"] for h in report["service_levels"]["by_hour"]) == result.sent
