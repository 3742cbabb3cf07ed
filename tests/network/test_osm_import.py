"""``routing-svc import-osm`` and OpenStreetMap uploads: a hand-made block, Bad Hersfeld,
and bad input on the command line and over HTTP."""

from __future__ import annotations

import functools
import gzip
import json
import math
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import pytest
import sumo
from fastapi.testclient import TestClient

from routing_svc.network.identity import network_sha256
from routing_svc.service.app import create_app
from routing_svc.service.settings import Settings

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared" / "nets"
MIB = 1024 * 1024

# A block of about 200 m x 200 m near (9.70, 50.86): corners A (1, south-west), B (2, south-east),
# C (3, north-east), D (4, north-west). Ways: A-B, B-C, C-D two-way streets of three different
# kinds (so that no corner is a mere geometry point); D-A one-way from D to A.
CORNERS = {"1": (50.8600, 9.7000), "2": (50.8600, 9.7028), "3": (50.8618, 9.7028)}
CORNERS["4"] = (50.8618, 9.7000)


def block_osm() -> bytes:
    """The square block, as OpenStreetMap XML."""
    nodes = "".join(
        f'<node id="{i}" version="1" lat="{lat}" lon="{lon}"/>' for i, (lat, lon) in CORNERS.items()
    )
    ways = []
    streets = [("1", "2", "residential"), ("2", "3", "tertiary"), ("3", "4", "secondary")]
    for way, (a, b, kind) in enumerate([*streets, ("4", "1", "unclassified")], start=10):
        oneway = way == 13
        tags = f'<tag k="highway" v="{kind}"/>'
        if oneway:
            tags += '<tag k="oneway" v="yes"/>'
        ways.append(f'<way id="{way}" version="1"><nd ref="{a}"/><nd ref="{b}"/>{tags}</way>')
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n<osm version="0.6">'
        '<bounds minlat="50.8595" minlon="9.6995" maxlat="50.8623" maxlon="9.7033"/>'
        f"{nodes}{''.join(ways)}</osm>\n"
    ).encode()


def cli(*args: str, cache: Path) -> subprocess.CompletedProcess[str]:
    """``routing-svc ARGS`` in a fresh process, compiled networks cached under ``cache``."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "ROUTING_SVC_CACHE": str(cache)}
    return subprocess.run(
        [sys.executable, "-m", "routing_svc.cli", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        check=False,
    )


@functools.cache
def bad_inputs() -> dict[str, bytes]:
    """Files that must be refused, by name."""
    laughs = (
        b'<?xml version="1.0"?><!DOCTYPE osm [<!ENTITY a "aaaaaaaaaa">'
        b'<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
        b'<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">]><osm>&c;</osm>'
    )
    filler = b'<tag k="a" v="b"/>\n' * (8 * MIB // 19)  # within every XML limit but size
    bomb = gzip.compress(b'<osm version="0.6">' + filler + b"</osm>")
    return {
        "not-osm": b'<?xml version="1.0"?><gpx version="1.1"></gpx>',
        "not-xml": b"this is not XML at all\n",
        "empty": b"",
        "truncated-gzip": gzip.compress(block_osm())[:-20],
        "billion-laughs": laughs,
        "gzip-bomb": bomb,
    }


EXPECTED = {
    "not-osm": "root element is <gpx>",
    "not-xml": "malformed",
    "empty": "empty",
    "truncated-gzip": "gzip",
    "billion-laughs": "DOCTYPE",
    "gzip-bomb": "larger than",
}


def test_block_gives_the_junctions_edges_and_one_way_direction(tmp_path: Path) -> None:
    source = tmp_path / "block.osm.xml"
    source.write_bytes(block_osm())
    out = cli(
        "import-osm",
        str(source),
        "-o",
        str(tmp_path / "block.net.xml.gz"),
        "--json",
        cache=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    # three two-way streets (two edges each) and one one-way street; four corner junctions
    assert summary["junctions"] == 4 and summary["edges"] == 7
    assert summary["car_edges"] == 7 and summary["car_component_junctions"] == 4
    root = ET.fromstring(gzip.decompress((tmp_path / "block.net.xml.gz").read_bytes()))
    roads = [e for e in root.iter("edge") if e.get("function") != "internal"]
    one_way = [e for e in roads if _way(e) == "13"]
    assert len(one_way) == 1 and sorted(_way(e) for e in roads).count("10") == 2
    xy = {j.get("id"): (float(j.get("x", 0)), float(j.get("y", 0))) for j in root.iter("junction")}
    start, end = xy[one_way[0].get("from")], xy[one_way[0].get("to")]
    assert end[1] < start[1] - 150.0  # D (north-west) to A (south-west): southward


def _way(edge: ET.Element) -> str:
    return (edge.get("id") or "").lstrip("-").split("#")[0]


def _lonlat_box(path: Path) -> tuple[float, ...]:
    with gzip.open(path, "rb") as handle:
        for _, element in ET.iterparse(handle):
            if element.tag == "location":
                return tuple(float(v) for v in element.get("origBoundary", "").split(","))
    raise AssertionError("no <location>")


def _metres(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    lat = math.radians((a[1] + b[1]) / 2)
    return math.hypot((a[0] - b[0]) * 111_320 * math.cos(lat), (a[1] - b[1]) * 110_540)


def test_bad_hersfeld_matches_the_shipped_network(tmp_path: Path) -> None:
    """Same area as DLR's network of the same extract, car counts in the same range
    (``shared/nets/README.md``: 4,057 car edges, about 1,865 junctions in the car component)."""
    out = tmp_path / "bh.net.xml.gz"
    source = SHARED / "badhersfeld.osm.xml.gz"
    done = cli("import-osm", str(source), "-o", str(out), "--json", cache=tmp_path)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    mine, shipped = _lonlat_box(out), _lonlat_box(SHARED / "badhersfeld.net.xml.gz")
    assert _metres(mine[:2], shipped[:2]) < 300 and _metres(mine[2:], shipped[2:]) < 300
    assert 0.8 < summary["car_edges"] / 4057 < 1.25
    assert 0.8 < summary["car_component_junctions"] / 1865 < 1.25
    assert (
        summary["car_component_edges"] + summary["car_edges_outside_component"]
        == (summary["car_edges"])
    )
    log = summary["netconvert"]
    assert log["warning_count"] == sum(log["warnings"].values()) > 0


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_bad_files_are_refused_on_the_command_line(tmp_path: Path, name: str) -> None:
    source = tmp_path / f"{name}.osm.gz"
    source.write_bytes(bad_inputs()[name])
    target = tmp_path / "out" / "x.net.xml.gz"
    out = cli(
        "import-osm", str(source), "-o", str(target), "--max-bytes", str(4 * MIB), cache=tmp_path
    )
    assert out.returncode == 2, out.stdout
    assert EXPECTED[name].lower() in out.stderr.lower() and "Traceback" not in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    assert not target.exists() and not any((tmp_path / "out").glob("*"))


@pytest.fixture
def osm_client(tmp_path: Path) -> Iterator[TestClient]:
    settings = Settings(
        database_url=f"sqlite:///{tmp_path / 'db.sqlite'}",
        networks={},
        data_dir=tmp_path / "networks",
        max_network_bytes=4 * MIB,
    )
    with TestClient(create_app(settings)) as client:
        yield client


def test_an_osm_upload_answers_like_a_network_upload(osm_client: TestClient) -> None:
    first = osm_client.post("/v1/networks", content=gzip.compress(block_osm()))
    assert first.status_code == 201, first.text
    body = first.json()
    assert body["junctions"] == 4 and body["edges"] == 7 and body["has_projection"]
    again = osm_client.post("/v1/networks", content=block_osm())
    assert again.status_code == 200 and again.json()["id"] == body["id"]
    listed = osm_client.get("/v1/networks").json()["items"]
    assert [n["id"] for n in listed] == [body["id"]]


def test_one_extract_is_one_network_on_the_command_line_and_over_http(
    osm_client: TestClient, tmp_path: Path
) -> None:
    """The same bytes, so the same identity (``network_sha256``), however and whenever
    the extract is converted: no time stamp and no install or temporary path."""
    source = tmp_path / "block.osm.xml"
    source.write_bytes(block_osm())
    written = []
    for name in ("first", "second"):
        target = tmp_path / name / "block.net.xml.gz"
        done = cli("import-osm", str(source), "-o", str(target), "--json", cache=tmp_path)
        assert done.returncode == 0, done.stderr
        written.append(target.read_bytes())
        assert json.loads(done.stdout)["sha256"] == network_sha256(target)
    assert written[0] == written[1]
    header = gzip.decompress(written[0])[:4000].decode()
    assert "<!-- generated by Eclipse SUMO netconvert" in header
    assert "generated on" not in header and str(tmp_path) not in header
    assert str(Path(sumo.SUMO_HOME)) not in header
    uploaded = osm_client.post("/v1/networks", content=block_osm())
    assert uploaded.status_code == 201, uploaded.text
    assert uploaded.json()["sha256"] == network_sha256(tmp_path / "first" / "block.net.xml.gz")


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_bad_osm_uploads_are_problems_and_store_nothing(
    osm_client: TestClient, tmp_path: Path, name: str
) -> None:
    answer = osm_client.post("/v1/networks", content=bad_inputs()[name])
    assert answer.status_code in (413, 422), answer.text
    assert answer.headers["content-type"].startswith("application/problem+json")
    assert osm_client.get("/v1/networks").json()["items"] == []
    assert not list((tmp_path / "networks").glob("*.net.xml"))
