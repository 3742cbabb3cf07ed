"""Importing a history in process: the place forms, time order, bad rows, idempotency."""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import numpy as np
import pytest

from routing_svc.errors import InvalidInput, UnknownEdge
from routing_svc.history import (
    HistoryInterrupted,
    HistoryRefused,
    InProcessHistoryClient,
    place_locally,
    read_calls,
    replay_history,
)
from routing_svc.history.replay import CallChunk, chunk_key
from routing_svc.network import CompiledNetwork
from routing_svc.network.snapping import point_on_edge
from routing_svc.service.schemas import MAX_EDGE_ID, TargetSpec
from tests.history.conftest import (
    DRT,
    cli,
    fleet_at,
    random_calls,
    write_csv,
    write_edge_calls,
)


def _import(client: InProcessHistoryClient, path: Path, fleet: str, **options: object):  # type: ignore[no-untyped-def]
    table = read_calls(path)
    runtime = client.get_fleet(fleet)
    entry = client.service.network("drt")
    placed = place_locally(table, entry, vehicle_types=[v["type"] for v in runtime["vehicles"]])
    return replay_history(table, placed, client, fleet, progress=False, **options)  # type: ignore[arg-type]


def _event_targets(client: InProcessHistoryClient, fleet: str) -> list[tuple[str, float]]:
    events = client.service.events(fleet, after=1, limit=100_000)
    return [(e["payload"]["target"]["edge"], e["payload"]["target"]["offset"]) for e in events]


def test_lonlat_xy_and_edge_places_land_where_the_calls_are(
    tmp_path: Path, client: InProcessHistoryClient, drt: CompiledNetwork
) -> None:
    calls = random_calls(drt, 60, seed=1)
    forms = {
        "lonlat": (["time", "lon", "lat"], [[c["time"], c["lon"], c["lat"]] for c in calls]),
        "xy": (["Time", "X", "Y"], [[c["time"], c["x"], c["y"]] for c in calls]),
        "edge": (["time", "edge", "offset"], [[c["time"], c["edge"], c["offset"]] for c in calls]),
    }
    for name, (header, rows) in forms.items():
        table = read_calls(write_csv(tmp_path / f"{name}.csv", header, rows))
        placed = place_locally(table, client.service.network("drt"), vehicle_types=["default"])
        assert not placed.bad and len(placed.edges) == 60
        for c, edge, offset in zip(calls, placed.edges, placed.offsets, strict=True):
            if name == "edge":
                assert (edge, offset) == (c["edge"], c["offset"])
            else:  # the snapped position is where the call is (to rounding of lon/lat)
                x, y = point_on_edge(drt, drt.edge_index[edge], offset)
                assert math.hypot(x - c["x"], y - c["y"]) < 0.01
    client.create_fleet(fleet_at([(calls[0]["edge"], 0.0), (calls[1]["edge"], 0.0)]))
    result = _import(client, tmp_path / "lonlat.csv", "f", chunk_size=25)
    assert (result.sent, result.applied, result.chunks) == (60, 60, 3)
    assert client.get_fleet("f")["version"] == 61


def test_edge_places_are_resolved_as_the_route_resolves_each_one(
    tmp_path: Path, client: InProcessHistoryClient, drt: CompiledNetwork
) -> None:
    calls = random_calls(drt, 40, seed=11)
    rows: list[list[object]] = [[c["time"], c["edge"], c["offset"]] for c in calls]
    end = drt.edge_ids[3]
    rows += [
        [1.0, end, float(drt.length[3])],  # the edge's very end
        [2.0, end, float(drt.length[3]) + 0.01],  # past it
        [3.0, end, "-0.0"],  # the edge's start
        [4.0, end, 0],
        [5.0, "no-such-edge", 1.0],
        [6.0, "x" * 5_000, 1.0],  # an id longer than the route takes
    ]
    table = read_calls(write_csv(tmp_path / "edges.csv", ["time", "edge", "offset"], rows))
    entry = client.service.network("drt")
    placed = place_locally(table, entry, vehicle_types=None)
    expected: list[tuple[str, float]] = []
    failed: list[int] = []
    for row in range(len(table)):  # the route's resolution, one row at a time
        edge, offset = table.edges[row], float(table.second[row])
        try:
            if len(edge) > MAX_EDGE_ID:  # the route's model refuses it
                raise InvalidInput("too long")
            position = entry.resolve_edge(edge, offset)
        except (InvalidInput, UnknownEdge):
            failed.append(int(table.lines[row]))
            continue
        expected.append((drt.edge_ids[position.edge], position.offset))
    assert list(zip(placed.edges, placed.offsets, strict=True)) == expected
    assert [r.line for r in placed.bad] == failed == [43, 46, 47]
    assert all(math.copysign(1.0, o) == 1.0 for o in placed.offsets)  # no -0.0 is sent
    assert "beyond the end" in placed.bad[0].reason and "no-such-edge" in placed.bad[1].reason


def test_an_unsorted_file_is_replayed_in_time_order(
    tmp_path: Path, client: InProcessHistoryClient, drt: CompiledNetwork
) -> None:
    calls = random_calls(drt, 40, seed=2)  # random times, in file order
    start = datetime(2024, 3, 1, tzinfo=UTC)
    iso = [(start + timedelta(seconds=int(c["time"]))).isoformat() for c in calls]
    path = write_csv(
        tmp_path / "calls.csv",
        ["time", "edge", "offset"],
        [[t, c["edge"], c["offset"]] for t, c in zip(iso, calls, strict=True)],
    )
    client.create_fleet(fleet_at([(calls[0]["edge"], 0.0)]))
    _import(client, path, "f", chunk_size=7)
    expected = [
        (c["edge"], c["offset"])
        for _, c in sorted(zip(iso, calls, strict=True), key=lambda p: p[0])
    ]
    assert expected != [(c["edge"], c["offset"]) for c in calls]
    assert _event_targets(client, "f") == expected


def _file_with_bad_rows(tmp_path: Path, drt: CompiledNetwork) -> Path:
    calls = random_calls(drt, 10, seed=3)
    rows: list[list[object]] = [[c["time"], c["lon"], c["lat"], ""] for c in calls]
    rows[1][0] = "yesterday"  # line 3: no time
    rows[3][1:3] = [0.0, 0.0]  # line 5: far off the map
    rows[5][3] = "Z"  # line 7: a type the fleet lacks
    rows[7][2] = "north"  # line 9: not a number
    return write_csv(tmp_path / "bad.csv", ["time", "lon", "lat", "types"], rows)


def test_refuse_imports_nothing_and_names_the_lines(
    tmp_path: Path, client: InProcessHistoryClient, drt: CompiledNetwork
) -> None:
    path = _file_with_bad_rows(tmp_path, drt)
    client.create_fleet(fleet_at([(drt.edge_ids[0], 0.0)]))
    before = client.get_fleet("f")
    with pytest.raises(HistoryRefused) as refused:
        _import(client, path, "f")
    assert [r.line for r in refused.value.bad] == [3, 5, 7, 9]
    assert client.get_fleet("f") == before
    skipped = _import(client, path, "f", on_bad_row="skip")
    assert [r.line for r in skipped.bad] == [3, 5, 7, 9]
    assert (skipped.sent, skipped.applied) == (6, 6)
    assert client.get_fleet("f")["version"] == before["version"] + 6


def test_refuse_on_the_command_line_exits_2_with_the_lines(
    tmp_path: Path, drt: CompiledNetwork
) -> None:
    path = _file_with_bad_rows(tmp_path, drt)
    db = str(tmp_path / "cli.db")
    created = cli(
        "history",
        "create-fleet",
        str(path),
        "--fleet",
        "f",
        "--net",
        "drt=drt",
        "--vehicles",
        "2",
        "--db",
        db,
        "--on-bad-row",
        "skip",
    )
    assert created.returncode == 0, created.stderr
    assert [r["line"] for r in json.loads(created.stdout)["bad_rows"]] == [3, 5, 7, 9]
    out = cli("history", "import", str(path), "--fleet", "f", "--db", db, "--quiet")
    assert out.returncode == 2
    assert all(f"line {n}:" in out.stderr for n in (3, 5, 7, 9))
    negative = cli(
        "history", "import", str(path), "--fleet", "f", "--db", db, "--quiet",
        "--on-bad-row", "skip", "--consolidation-workers", "-1",
    )  # fmt: skip
    assert negative.returncode == 2
    assert "--consolidation-workers must be >= 0, got -1" in negative.stderr
    again = cli(
        "history",
        "import",
        str(path),
        "--fleet",
        "f",
        "--db",
        db,
        "--quiet",
        "--on-bad-row",
        "skip",
    )
    assert again.returncode == 0, again.stderr
    summary = json.loads(again.stdout)
    assert summary["version_before"] == 1 and summary["version_after"] == 7


def test_a_rerun_after_a_crash_applies_each_chunk_once(
    tmp_path: Path, client: InProcessHistoryClient, drt: CompiledNetwork
) -> None:
    calls = random_calls(drt, 50, seed=4)
    path = write_edge_calls(tmp_path / "calls.csv", calls)
    client.create_fleet(fleet_at([(calls[0]["edge"], 0.0), (calls[1]["edge"], 0.0)]))
    # the first chunk went through before the crash
    table = read_calls(path)
    first = sorted(calls, key=lambda c: c["time"])[:20]
    client.post_batch(
        "f",
        [{"position": {"edge": c["edge"], "offset": c["offset"]}} for c in first],
        idempotency_key=chunk_key(table.sha256, 20, 0),
    )
    resumed = _import(client, path, "f", chunk_size=20)
    assert (resumed.applied, resumed.applied_chunks, resumed.version_after) == (30, 2, 51)
    state = client.get_fleet("f")
    again = _import(client, path, "f", chunk_size=20)
    assert (again.applied, again.version_after) == (0, 51)
    assert client.get_fleet("f") == state
    assert list(again.costs) == list(resumed.costs)  # the stored answers


def test_a_live_server_creates_the_fleet_the_process_creates_skipping_the_same_rows(
    tmp_path: Path, drt: CompiledNetwork, live_server: Callable[[], str]
) -> None:
    path = _file_with_bad_rows(tmp_path, drt)
    create = ["history", "create-fleet", str(path), "--fleet", "f", "--vehicles", "2", "--quiet"]
    local = cli(
        *create, "--net", "drt=drt", "--db", str(tmp_path / "local.db"), "--on-bad-row", "skip"
    )
    assert local.returncode == 0, local.stderr
    url = live_server()
    remote = [*create, "--net", "drt", "--service-url", url]
    refused = cli(*remote)
    assert refused.returncode == 2
    assert all(f"line {n}:" in refused.stderr for n in (3, 5, 7, 9))
    assert httpx.get(f"{url}/v1/fleets/f").status_code == 404  # nothing was created
    skipped = cli(*remote, "--on-bad-row", "skip")
    assert skipped.returncode == 0, skipped.stderr
    # the same rows are left out (line 7 requires a type the new fleet lacks), so the same
    # sample gives the same fleet
    lines = [[r["line"] for r in json.loads(out.stdout)["bad_rows"]] for out in (skipped, local)]
    assert lines == [[3, 5, 7, 9], [3, 5, 7, 9]]
    assert json.loads(skipped.stdout)["vehicles"] == json.loads(local.stdout)["vehicles"]


def test_an_import_whose_consolidations_a_worker_solves_applies_each_call_once_and_replays(
    tmp_path: Path, drt: CompiledNetwork
) -> None:
    calls = random_calls(drt, 2_000, seed=5)
    path = write_edge_calls(tmp_path / "calls.csv", calls)
    with InProcessHistoryClient(
        database_url=f"sqlite:///{tmp_path / 'e.db'}", consolidation_workers=1
    ) as client:
        assert client.service.solver is not None
        client.add_network(DRT, name="drt")
        starts = [(calls[i]["edge"], 0.0) for i in range(4)]
        client.create_fleet(fleet_at(starts, rule="consolidating"))
        result = _import(client, path, "f", chunk_size=100)
        assert (result.applied, result.version_after) == (2_000, 2_001)
        in_order = sorted(calls, key=lambda c: c["time"])
        assert _event_targets(client, "f") == [(c["edge"], c["offset"]) for c in in_order]
        events = client.service.events("f", after=1, limit=10_000)
        recorded = [e["seq"] for e in events if e["result"].get("consolidated")]
        # due at 250 targets, applied at once; the next ones by the end of the period
        # after them at the latest: by 750, 1,250 and 1,750 targets
        assert len(recorded) >= 4
        assert client.service.verify("f")["snapshot_identical"] is True
        state = client.get_fleet("f")
        again = _import(client, path, "f", chunk_size=100)
        assert (again.applied, again.version_after) == (0, 2_001)
        assert client.get_fleet("f") == state


@pytest.mark.parametrize(
    ("offset", "requires"), [(12.5, None), (0, None), (3.0, ("a", "b")), (7.25, ("a",))]
)
def test_a_chunk_target_is_the_body_the_route_validates(
    offset: float, requires: tuple[str, ...] | None
) -> None:
    chunk = CallChunk(["e1"], [offset], [requires])
    sent = {"position": {"edge": "e1", "offset": offset}, "requires": requires}
    validated = TargetSpec.model_validate(sent).model_dump(mode="json")
    assert chunk.targets() == [validated]
    assert json.dumps(chunk.targets()) == json.dumps([validated])  # 0 is written 0.0 by both


def test_a_chunk_and_the_batch_route_share_keys_and_a_bad_chunk_applies_nothing(
    client: InProcessHistoryClient, drt: CompiledNetwork
) -> None:
    calls = random_calls(drt, 30, seed=6)
    client.create_fleet(fleet_at([(calls[0]["edge"], 0.0), (calls[1]["edge"], 0.0)]))
    chunk = CallChunk([c["edge"] for c in calls], [c["offset"] for c in calls], [None] * 30)
    answer = client.post_chunk("f", chunk, idempotency_key="k1")
    assert (answer.first_seq, answer.version) == (2, 31)
    state = client.get_fleet("f")
    # the same calls through the route's body model: answered from the log
    results, version = client.post_batch("f", chunk.targets(), idempotency_key="k1")
    assert version == 31 and [r["cost"] for r in results] == answer.costs
    assert [r["seq"] for r in results] == list(range(2, 32))
    assert client.get_fleet("f") == state
    for edges, offsets, refused in (
        ([calls[0]["edge"], "no-such-edge"], [1.0, 1.0], UnknownEdge),
        ([calls[0]["edge"], calls[1]["edge"]], [1.0, 1e9], InvalidInput),
        ([calls[0]["edge"], calls[1]["edge"]], [1.0, math.nan], InvalidInput),
    ):
        with pytest.raises(refused):
            client.post_chunk("f", CallChunk(edges, offsets, [None, None]), idempotency_key="k2")
    assert client.get_fleet("f") == state


def test_a_chunk_that_fails_stops_the_import_with_every_chunk_before_it_applied_and_none_after(
    tmp_path: Path, client: InProcessHistoryClient, drt: CompiledNetwork
) -> None:
    calls = random_calls(drt, 50, seed=8)
    path = write_edge_calls(tmp_path / "calls.csv", calls)
    client.create_fleet(fleet_at([(calls[0]["edge"], 0.0), (calls[1]["edge"], 0.0)]))
    table = read_calls(path)
    placed = place_locally(table, client.service.network("drt"), vehicle_types=None)
    order = np.argsort(table.seconds[placed.rows], kind="stable")
    broken = copy.deepcopy(placed)
    broken.edges[int(order[32])] = "no-such-edge"  # in chunk 4 of 5 (10 calls each)
    with pytest.raises(HistoryInterrupted) as interrupted:
        replay_history(table, broken, client, "f", chunk_size=10, progress=False)
    assert interrupted.value.detail.startswith("chunk 4 of 5 failed (")
    assert interrupted.value.detail.endswith(
        "chunks 1 to 3 are applied, and the same command again applies each call once"
    )
    assert client.get_fleet("f")["version"] == 31  # chunk 4 applied nothing, chunk 5 was not sent
    in_order = sorted(calls, key=lambda c: c["time"])
    assert _event_targets(client, "f") == [(c["edge"], c["offset"]) for c in in_order[:30]]
    resumed = replay_history(table, placed, client, "f", chunk_size=10, progress=False)
    assert (resumed.applied, resumed.applied_chunks, resumed.version_after) == (20, 2, 51)
    assert _event_targets(client, "f") == [(c["edge"], c["offset"]) for c in in_order]
