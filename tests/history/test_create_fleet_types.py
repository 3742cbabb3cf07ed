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
