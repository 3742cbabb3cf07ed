"""``routing-svc cosim --stands``: on Bad Hersfeld with the shared parking file, the ``sa``
fleet's idle vehicles park in SUMO parkingAreas of the file that are its stands (read from
SUMO's own stop output), requests are still served, and a bad stands file ends with a
one-line error before anything is written."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from defusedxml import ElementTree

from routing_svc.sim import CosimResult, CosimSpec, parse_policies, run_cosim

SHARED = Path(__file__).resolve().parents[3] / "shared" / "nets"
BAD_HERSFELD = SHARED / "badhersfeld.net.xml.gz"
PARKING = SHARED / "badhersfeld.parking.add.xml"


def parking_areas(path: Path) -> dict[str, tuple[str, float]]:
    """Each parkingArea of the file: its edge and the middle of its span (as written)."""
    areas = {}
    for area in ElementTree.parse(path).getroot().iter("parkingArea"):
        edge = area.get("lane").rpartition("_")[0]
        middle = (float(area.get("startPos")) + float(area.get("endPos"))) / 2.0
        areas[area.get("id")] = (edge, middle)
    return areas


def small(policies: str) -> CosimSpec:
    """3 vehicles, 5 minutes of requests around one hotspot (short rides), the parking
    file's stands; the stands are recorded every 10 simulated seconds."""
    return CosimSpec(
        network=str(BAD_HERSFELD),
        vehicles=3,
        duration=300.0,
        warmup=60.0,
        drain=900.0,
        rate=30.0,
        demand="hotspots:1",
        ride_radius=500.0,
        history=30,
        density=2.0,
        policies=parse_policies(policies),
        seeds=(0,),
        workers=1,
        snapshot_period=10.0,
        stands=str(PARKING),
    )


def fleet_stops(path: Path) -> list[dict[str, str]]:
    """The fleet's stops in SUMO's stop output, in its order."""
    stops = ElementTree.parse(path).getroot().iter("stopinfo")
    return [dict(s.attrib) for s in stops if s.get("id", "").startswith("fleet")]


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[CosimResult, Path]:
    out = tmp_path_factory.mktemp("stands")
    return run_cosim(small("sa,optimum"), out_dir=out, progress=False), out


def test_idle_vehicles_park_in_their_stands_and_requests_are_served(
    run: tuple[CosimResult, Path],
) -> None:
    result, out = run
    areas = parking_areas(PARKING)
    (sa,) = [r for r in result.runs if r.policy == "sa"]
    parked = [s for s in fleet_stops(out / "seed0" / "stops-sa.xml") if s.get("parkingArea")]
    assert parked, "no fleet vehicle parked in a parkingArea"
    assert {s["parkingArea"] for s in parked} <= set(areas)
    # every reference the fleet gave its vehicles is a stand of the file
    stand_places = {(edge, round(middle, 6)) for edge, middle in areas.values()}
    for _, positions in sa.snapshots:
        assert {(e, round(o, 6)) for e, o in positions.values()} <= stand_places
    # while a vehicle is parked in a parkingArea, that parkingArea is its stand
    end = result.spec.end
    checked = 0
    for stop in parked:
        started, ended = float(stop["started"]), float(stop["ended"])
        ended = end if ended < 0 else ended
        for time, positions in sa.snapshots:
            if started <= time < ended - 1.0:
                edge, offset = positions[stop["id"]]
                assert areas[stop["parkingArea"]][0] == edge
                assert areas[stop["parkingArea"]][1] == pytest.approx(offset)
                checked += 1
    assert checked > 0
    # vehicles came back from a ride and parked (not only where they were inserted)
    assert any(float(s["started"]) > result.spec.warmup for s in parked)
    # dispatch: vehicles left their parkingAreas to serve, as the service named them
    assert any(0 < float(s["ended"]) < result.spec.end - 1.0 for s in parked)
    assert sa.served >= 1
    assert sa.fallbacks == 0 and sa.lost == 0 and sa.unparked == 0


def test_the_summary_names_the_stands_file(run: tuple[CosimResult, Path]) -> None:
    _, out = run
    summary = json.loads((out / "summary.json").read_text())
    usable = len(parking_areas(PARKING)) - summary["stands"]["dropped"]
    assert summary["stands"]["file"] == str(PARKING)
    assert summary["stands"]["usable"] == usable > 0
    assert summary["spec"]["stands"] == str(PARKING)
    assert summary["policies"]["sa"]["unparked"] == 0


def test_sumo_taxistand_parks_at_the_stands_of_the_file(tmp_path: Path) -> None:
    """Taxis start in the parkingAreas of the optimum over the stands and go back to them."""
    result = run_cosim(small("sumo-taxistand"), out_dir=tmp_path, progress=False)
    areas = parking_areas(PARKING)
    stand_places = {(edge, round(middle, 6)) for edge, middle in areas.values()}
    optimum, prepared = result.optimum[0], result.prepared
    assert optimum is not None and prepared is not None
    edges = prepared.network.edge_ids
    sites = {(edges[p.edge], round(p.offset, 6)) for p in optimum.positions}
    assert sites <= stand_places
    parked = [
        s
        for s in fleet_stops(tmp_path / "seed0" / "stops-sumo-taxistand.xml")
        if s.get("parkingArea")
    ]
    assert {s["parkingArea"] for s in parked} <= set(areas)
    first = {s["id"]: s["parkingArea"] for s in reversed(parked)}
    assert {(areas[a][0], round(areas[a][1], 6)) for a in first.values()} == sites
    assert any(float(s["started"]) > result.spec.warmup for s in parked)
    assert result.runs[0].served >= 1


def test_the_optimum_policy_waits_at_the_optimum_over_the_stands(
    run: tuple[CosimResult, Path],
) -> None:
    """``optimum``'s vehicles are the optimum over the stands, parked in their parkingAreas."""
    result, out = run
    areas = parking_areas(PARKING)
    optimum, prepared = result.optimum[0], result.prepared
    assert optimum is not None and prepared is not None
    edges = prepared.network.edge_ids
    sites = sorted((edges[p.edge], round(p.offset, 6)) for p in optimum.positions)
    assert set(sites) <= {(edge, round(middle, 6)) for edge, middle in areas.values()}
    (run_optimum,) = [r for r in result.runs if r.policy == "optimum"]
    for _, positions in run_optimum.snapshots:
        assert sorted((e, round(o, 6)) for e, o in positions.values()) == sites
    stops = fleet_stops(out / "seed0" / "stops-optimum.xml")
    first = {s["id"]: s["parkingArea"] for s in reversed(stops) if s.get("parkingArea")}
    assert sorted((areas[a][0], round(areas[a][1], 6)) for a in first.values()) == sites
    assert run_optimum.served >= 1


def cosim(*args: str) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "routing_svc.cli", "cosim", "--net", str(BAD_HERSFELD)]
    return subprocess.run([*command, *args], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (None, "no stands file at"),
        (
            '<additional><parkingArea id="p" lane="no_such_edge_0" roadsideCapacity="3"/>'
            "</additional>",
            "no stand of",
        ),
    ],
)
def test_a_bad_stands_file_is_a_one_line_error(
    tmp_path: Path, body: str | None, message: str
) -> None:
    stands = tmp_path / "stands.add.xml"
    if body is not None:
        stands.write_text(body)
    out = tmp_path / "out"
    done = cosim("--policies", "sa", "--stands", str(stands), "--out", str(out), "--quiet")
    assert done.returncode == 2
    assert done.stdout == ""
    assert len(done.stderr.strip().splitlines()) == 1
    assert message in done.stderr
    assert not out.exists()


def test_stand_homes_fill_parking_areas_at_one_stand_in_vehicle_order() -> None:
    """Two parkingAreas at one position are one stand of capacity 3 for the service;
    its vehicles, by id, fill the first parkingArea (room for 1), then the second."""
    from routing_svc.network import load_network
    from routing_svc.network.stands import Stand
    from routing_svc.service.inprocess import InProcessFleetClient
    from routing_svc.sim.dispatcher import stand_homes

    network = load_network(BAD_HERSFELD)
    edge = max(range(network.n_edges), key=lambda i: float(network.length[i]))
    name, middle = network.edge_ids[edge], float(network.length[edge]) / 2.0
    areas = [Stand("a", name, middle, 1), Stand("b", name, middle, 2)]
    with InProcessFleetClient() as client:
        network_id = str(client.add_network(BAD_HERSFELD, name="bh")["id"])
        vehicles = [{"id": v, "position": {"edge": name, "offset": middle}} for v in "zxy"]
        client.create_fleet(
            {
                "id": "f",
                "network": network_id,
                "vehicles": vehicles,
                "stands": [s.to_dict() for s in areas],
            }
        )
        homes = stand_homes(client.get_fleet("f"), areas)
    assert {v: (p, a.id) for v, (p, a) in homes.items()} == {
        "x": ((name, middle), "a"),
        "y": ((name, middle), "b"),
        "z": ((name, middle), "b"),
    }
