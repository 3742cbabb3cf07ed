"""``history create-fleet`` against a live server checks each call's required types against
the vehicles the new fleet will have, and leaves out or refuses the same lines as in
process."""

from __future__ import annotations

import json
import re
from pathlib import Path

import httpx

from routing_svc.network import CompiledNetwork
from tests.helpers import LiveServer
from tests.history.conftest import cli, random_calls, write_csv

# the new fleet has two vehicles of the API's default type ("default")
TYPES = ["", "default", "default+default", "default default default", "Z", "default+Z", ""]
UNSERVED = {5, 6, 7}  # three defaults, a Z, a Z with a default: the lines of those calls
OFF_MAP = 8  # the last call is far off the map (and needs any one vehicle)


def calls_file(tmp_path: Path, drt: CompiledNetwork) -> Path:
    calls = random_calls(drt, len(TYPES), seed=11)
    rows: list[list[object]] = [
        [c["time"], c["lon"], c["lat"], t] for c, t in zip(calls, TYPES, strict=True)
    ]
    rows[-1][1:3] = [0.0, 0.0]
    return write_csv(tmp_path / "typed.csv", ["time", "lon", "lat", "types"], rows)


def test_a_server_refuses_or_skips_the_calls_the_new_fleet_cannot_serve(
    tmp_path: Path, drt: CompiledNetwork
) -> None:
    path = calls_file(tmp_path, drt)
    create = ["history", "create-fleet", str(path), "--fleet", "f", "--vehicles", "2", "--quiet"]
    bad = sorted(UNSERVED | {OFF_MAP})
    server = LiveServer(f"sqlite:///{tmp_path / 'server.db'}", tmp_path).start()
    try:
        remote = [*create, "--net", "drt", "--service-url", server.url]
        refused = cli(*remote)
        assert refused.returncode == 2
        assert [int(n) for n in re.findall(r"line (\d+):", refused.stderr)] == bad
        assert len(refused.stderr.splitlines()) == 1 and "type 'Z'" in refused.stderr
        assert httpx.get(f"{server.url}/v1/fleets/f").status_code == 404  # nothing created
        skipped = cli(*remote, "--on-bad-row", "skip")
        assert skipped.returncode == 0, skipped.stderr
        fleet = httpx.get(f"{server.url}/v1/fleets/f").json()
    finally:
        server.stop()
    report = json.loads(skipped.stdout)
    assert [r["line"] for r in report["bad_rows"]] == bad
    assert report["sample"] == len(TYPES) - len(bad)
    assert {v["type"] for v in fleet["vehicles"]} == {"default"} and len(fleet["vehicles"]) == 2
    local = cli(
        *create, "--net", "drt=drt", "--db", str(tmp_path / "local.db"), "--on-bad-row", "skip"
    )
    assert local.returncode == 0, local.stderr
    here = json.loads(local.stdout)
    # the same rows out for the same type reasons (the off-map reason is worded apart)
    assert [r for r in here["bad_rows"] if r["line"] in UNSERVED] == [
        r for r in report["bad_rows"] if r["line"] in UNSERVED
    ]
    assert [r["line"] for r in here["bad_rows"]] == bad
    assert (here["sample"], here["vehicles"]) == (report["sample"], report["vehicles"])


def test_a_fleet_of_several_types_starts_each_type_at_the_calls_that_needed_it(
    tmp_path: Path, drt: CompiledNetwork
) -> None:
    a_edges, b_edge = [drt.edge_ids[10], drt.edge_ids[200]], drt.edge_ids[400]
    rows: list[list[object]] = [[t, a_edges[t % 2], 0.0, "A"] for t in range(8)]
    rows += [[100 + t, b_edge, 0.0, "B"] for t in range(4)]
    path = write_csv(tmp_path / "ab.csv", ["time", "edge", "offset", "types"], rows)
    create = ["history", "create-fleet", str(path), "--fleet", "f", "--quiet"]
    local = cli(
        *create, "--net", "drt=drt", "--db", str(tmp_path / "l.db"), "--vehicles", "A:2,B:1"
    )
    assert local.returncode == 0, local.stderr
    server = LiveServer(f"sqlite:///{tmp_path / 'server.db'}", tmp_path).start()
    try:
        remote = [*create, "--net", "drt", "--service-url", server.url, "--vehicles", "A:2,B:1"]
        served = cli(*remote)
        assert served.returncode == 0, served.stderr
        fleet = httpx.get(f"{server.url}/v1/fleets/f").json()
    finally:
        server.stop()
    assert json.loads(local.stdout)["vehicles"] == json.loads(served.stdout)["vehicles"]
    kinds = {v["id"]: v["type"] for v in fleet["vehicles"]}
    assert kinds == {"v000": "A", "v001": "A", "v002": "B"}
    at = {v["id"]: v["position"]["edge"] for v in fleet["vehicles"]}
    # each type on its own calls' points; the one B would stand nearer the eight A calls
    # at the p-median of all twelve
    assert {at["v000"], at["v001"]} == set(a_edges) and at["v002"] == b_edge


def test_a_bad_vehicle_mix_is_refused_and_creates_nothing(
    tmp_path: Path, drt: CompiledNetwork
) -> None:
    path = calls_file(tmp_path, drt)
    db = str(tmp_path / "bad.db")
    for mix, said in [
        ("0", "--vehicles must be >= 1"),
        ("two", "a count or TYPE:COUNT"),
        ("A:2,A:1", "named once"),
        ("A:0", "count >= 1"),
        ("A:x", "is not TYPE:COUNT"),
    ]:
        out = cli("history", "create-fleet", str(path), "--fleet", "f", "--net", "drt=drt",
                  "--db", db, "--quiet", "--vehicles", mix)  # fmt: skip
        assert out.returncode == 2, (mix, out.stderr)
        assert said in out.stderr and "Traceback" not in out.stderr, (mix, out.stderr)
    # no fleet "f" was made: creating it now succeeds (a second would conflict)
    ok = ["history", "create-fleet", str(path), "--fleet", "f", "--net", "drt=drt"]
    ok += ["--db", db, "--quiet", "--vehicles", "2", "--on-bad-row", "skip"]
    assert cli(*ok).returncode == 0
    again = cli(*ok)
    assert again.returncode == 2 and "already exists" in again.stderr, again.stderr
