"""Stands from SUMO additional files and from positions: the shared Bad Hersfeld parking
file, each attribute rule of a parkingArea by hand, what is dropped, and the command."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.network.stands import Stand, read_stands_file, stands_on_network
from routing_svc.types import NetPosition

SHARED = Path(__file__).resolve().parents[3] / "shared" / "nets"
PARKING = SHARED / "badhersfeld.parking.add.xml"
BAD_HERSFELD = SHARED / "badhersfeld.net.xml.gz"
DRT = load_network(resolve_network("drt"))


@pytest.fixture(scope="module")
def bad_hersfeld() -> CompiledNetwork:
    return load_network(BAD_HERSFELD)


def test_the_shared_parking_file(bad_hersfeld: CompiledNetwork) -> None:
    areas = ET.parse(PARKING).getroot().findall("parkingArea")
    assert len(areas) == 409
    reading = read_stands_file(PARKING, bad_hersfeld)
    assert len(reading.usable) + len(reading.dropped) == 409
    # a stand is usable exactly when its lane's edge is an edge of the compiled network
    edges = {a.get("id"): str(a.get("lane")).rpartition("_")[0] for a in areas}
    usable_ids = {s.id for s in reading.usable}
    assert usable_ids == {i for i, e in edges.items() if e in bad_hersfeld.edge_index}
    assert len(reading.dropped) == 409 - len(usable_ids) > 0
    assert all("not on the network" in d.reason for d in reading.dropped)
    # every area of the file has roadsideCapacity 1000 and no <space> children
    assert {s.capacity for s in reading.usable} == {1000}
    assert reading.capacity == 1000 * len(reading.usable)
    by_id = {a.get("id"): a for a in areas}
    for stand in reading.usable:
        area = by_id[stand.id]
        middle = (float(area.get("startPos", "")) + float(area.get("endPos", ""))) / 2
        length = float(bad_hersfeld.length[bad_hersfeld.edge_index[stand.edge]])
        assert stand.offset == pytest.approx(min(max(middle, 0.0), length))
    positions = reading.positions(bad_hersfeld)
    assert positions[0] == NetPosition(bad_hersfeld.edge_index[reading.usable[0].edge],
                                       reading.usable[0].offset)  # fmt: skip


def write(path: Path, body: str) -> Path:
    path.write_text(f"<additional>\n{body}\n</additional>\n")
    return path


def test_each_rule_of_a_parking_area(tmp_path: Path) -> None:
    e0, e1, e2 = DRT.edge_ids[0], DRT.edge_ids[1], DRT.edge_ids[2]
    l0, l1, l2 = (float(DRT.length[i]) for i in range(3))
    source = write(
        tmp_path / "p.add.xml",
        f'<parkingArea id="a" lane="{e0}_0" startPos="2" endPos="6" roadsideCapacity="3"/>\n'
        f'<parkingArea id="b" lane="{e1}_1" roadsideCapacity="1">'
        '<space x="0" y="0"/><space x="1" y="1"/></parkingArea>\n'
        f'<parkingArea id="c" lane="{e2}_0" startPos="-4" endPos="-2" roadsideCapacity="2"/>\n'
        f'<parkingArea id="d" lane="{e0}_0" startPos="{l0 + 50}" endPos="{l0 + 60}" '
        'friendlyPos="true" roadsideCapacity="1"/>\n'
        f'<parkingArea id="e" lane="{e0}_0" startPos="{l0 + 50}" endPos="{l0 + 60}" '
        'roadsideCapacity="1"/>\n'
        f'<parkingArea id="f" lane="{e1}_0" startPos="1" endPos="2"/>\n'
        '<parkingArea id="g" lane="no_such_edge_0" startPos="1" endPos="2" roadsideCapacity="4"/>',
    )
    reading = read_stands_file(source, DRT)
    assert reading.usable == (
        Stand("a", e0, 4.0, 3),
        Stand("b", e1, l1 / 2, 3),  # no positions: the whole lane; 1 + two <space>
        Stand("c", e2, l2 - 3.0, 2),  # negative positions count from the lane's end
        Stand("d", e0, l0, 1),  # friendlyPos moves it onto the lane
    )
    assert [(d.id, d.edge) for d in reading.dropped] == [
        ("e", e0), ("f", e1), ("g", "no_such_edge"),
    ]  # fmt: skip
    reasons = [d.reason for d in reading.dropped]
    assert "off the edge" in reasons[0]
    assert reasons[1] == "no capacity"
    assert "not on the network" in reasons[2]


@pytest.mark.parametrize(
    "body",
    [
        "<net/>",
        "<additional><parkingArea id='x'/>",
        "<!DOCTYPE a [<!ENTITY e 'x'>]><additional/>",
    ],
)
def test_a_file_that_is_not_an_additional_file(tmp_path: Path, body: str) -> None:
    source = tmp_path / "bad.add.xml"
    source.write_text(body)
    with pytest.raises(InvalidInput, match="not a SUMO additional file"):
        read_stands_file(source, DRT)


def test_a_parking_area_without_a_lane_or_with_a_bad_number(tmp_path: Path) -> None:
    with pytest.raises(InvalidInput, match="'id' and a 'lane'"):
        read_stands_file(write(tmp_path / "a.xml", '<parkingArea id="x"/>'), DRT)
    bad = f'<parkingArea id="x" lane="{DRT.edge_ids[0]}_0" startPos="one"/>'
    with pytest.raises(InvalidInput, match="not a number"):
        read_stands_file(write(tmp_path / "b.xml", bad), DRT)


def test_stands_from_positions() -> None:
    e0 = DRT.edge_ids[0]
    reading = stands_on_network(
        [Stand("1", e0, 0.0, 2), Stand("2", e0, -1.0, 2), Stand("3", e0, 1.0, 0),
         Stand("4", "nowhere", 0.0, 1), Stand("5", e0, float("nan"), 1)],
        DRT,
    )  # fmt: skip
    assert [s.id for s in reading.usable] == ["1"]
    assert [d.id for d in reading.dropped] == ["2", "3", "4", "5"]


def test_the_stands_command(tmp_path: Path) -> None:
    e0, e1 = DRT.edge_ids[0], DRT.edge_ids[1]
    source = write(
        tmp_path / "p.add.xml",
        f'<parkingArea id="a" lane="{e0}_0" startPos="2" endPos="6" roadsideCapacity="3"/>\n'
        f'<parkingArea id="b" lane="{e1}_0" startPos="1" endPos="2"/>',
    )
    command = [sys.executable, "-m", "routing_svc.cli", "stands", str(source), "--net", "drt"]
    done = subprocess.run([*command, "--json"], capture_output=True, text=True, check=True)
    report = json.loads(done.stdout)
    assert report["stands"] == [{"edge": e0, "offset": 4.0, "capacity": 3}]
    assert report["dropped"] == [{"id": "b", "edge": e1, "reason": "no capacity"}]
    text = subprocess.run(command, capture_output=True, text=True, check=True).stdout
    assert text.splitlines()[0] == "1 usable stands (capacity 3), 1 dropped"
    wrong = subprocess.run(
        [*command[:4], str(resolve_network("drt")), "--net", "drt"], capture_output=True, text=True
    )
    assert wrong.returncode == 2
    assert re.search(r"not a SUMO additional file", wrong.stderr)
    missing = subprocess.run(
        [*command[:4], str(tmp_path / "none.add.xml"), "--net", "drt"],
        capture_output=True,
        text=True,
    )
    assert missing.returncode == 2
    assert missing.stderr.splitlines() == [
        f"routing-svc stands: invalid input: no stands file at {tmp_path / 'none.add.xml'}"
    ]
