"""The one demand-spec parser, the buildings demand and the time-of-day profile."""

from __future__ import annotations

import csv
import logging
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from routing_svc.demand import network_demand, parse_demand_spec
from routing_svc.demand.profile import HourlyProfile, read_profile
from routing_svc.demand.spec import (
    BuildingsFile,
    EdgeWeights,
    Hotspots,
    Uniform,
    WeightsFile,
    recipe_from_reference,
)
from routing_svc.errors import InvalidInput, UnknownEdge
from routing_svc.network import CompiledNetwork, load_network
from routing_svc.sim.requests import Destinations, Phase, person_requests

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "nets"
BUILDINGS = SHARED / "badhersfeld.buildings.csv"


@pytest.fixture(scope="module")
def badhersfeld(tmp_path_factory: pytest.TempPathFactory) -> CompiledNetwork:
    return load_network(SHARED / "badhersfeld.net.xml.gz", cache_dir=tmp_path_factory.mktemp("c"))


def test_the_grammar(tmp_path: Path) -> None:
    weights = tmp_path / "w.csv"
    weights.write_text("edge,weight\n")
    assert parse_demand_spec("uniform").form == Uniform()
    assert parse_demand_spec("hotspots").form == Hotspots(3)
    assert parse_demand_spec("hotspots:7").form == Hotspots(7)
    assert parse_demand_spec(str(weights)).form == WeightsFile(weights)
    assert parse_demand_spec(f"weights:{weights}").form == WeightsFile(weights)
    assert parse_demand_spec(f"buildings:{BUILDINGS}").form == BuildingsFile(BUILDINGS)
    profile = tmp_path / "day.csv"
    profile.write_text("# hourly\n" + ",".join(["1"] * 12) + "\n" + "\n".join(["3"] * 12) + "\n")
    recipe = parse_demand_spec(f"buildings:{BUILDINGS}?profile={profile}")
    assert recipe.form == BuildingsFile(BUILDINGS)
    assert recipe.profile == HourlyProfile((1.0,) * 12 + (3.0,) * 12)


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("nowhere.csv", "--demand must be"),
        ("hotspots:x", "integer K >= 1"),
        ("hotspots:0", "integer K >= 1"),
        ("buildings:/no/such.csv", "no file"),
        ("uniform?profile=", "24 hourly weights"),
        ("uniform?profile=/no/such.csv", "does not exist"),
        ("", "--demand must be"),
    ],
)
def test_bad_specs_say_what_is_wrong(spec: str, message: str) -> None:
    with pytest.raises(InvalidInput, match=message):
        parse_demand_spec(spec)


def test_profile_needs_24_numbers(tmp_path: Path) -> None:
    short = tmp_path / "short.csv"
    short.write_text("1,2,3\n")
    with pytest.raises(InvalidInput, match="24 hourly weights, got 3"):
        read_profile(short)
    words = tmp_path / "words.csv"
    words.write_text("a" + ",1" * 23)
    with pytest.raises(InvalidInput, match="line 1"):
        read_profile(words)
    assert HourlyProfile((0.0,) * 23 + (2.0,)).factor(23.5 * 3600) == 24.0


def test_reference_form_uses_the_same_builder(badhersfeld: CompiledNetwork) -> None:
    edge = badhersfeld.edge_ids[5]
    recipe = recipe_from_reference({"kind": "weights", "weights": {edge: 2.0}})
    assert recipe.form == EdgeWeights({edge: 2.0})
    dist = network_demand(badhersfeld, recipe, rng=np.random.default_rng(0))
    assert {p.edge for p in dist.positions} == {5}
    with pytest.raises(UnknownEdge):
        network_demand(
            badhersfeld,
            recipe_from_reference({"kind": "weights", "weights": {"nope": 1.0}}),
            rng=np.random.default_rng(0),
        )
    a = network_demand(
        badhersfeld,
        recipe_from_reference({"kind": "hotspots", "count": 2}),
        rng=np.random.default_rng(4),
    )
    b = network_demand(badhersfeld, parse_demand_spec("hotspots:2"), rng=np.random.default_rng(4))
    assert a.positions == b.positions and np.array_equal(a.weights, b.weights)


def test_buildings_demand_matches_the_file(
    badhersfeld: CompiledNetwork, caplog: pytest.LogCaptureFixture
) -> None:
    """Edge masses equal the summed Weight of the buildings on the kept edges, renormalised."""
    per_edge: dict[str, float] = defaultdict(float)
    with BUILDINGS.open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 11270
    for row in rows:
        per_edge[row["GenEdge"]] += float(row["Weight"])
    kept = {e: w for e, w in per_edge.items() if e in badhersfeld.edge_index and w > 0}
    total = sum(kept.values())
    with caplog.at_level(logging.WARNING, logger="routing_svc.demand"):
        dist = network_demand(
            badhersfeld, parse_demand_spec(f"buildings:{BUILDINGS}"), rng=np.random.default_rng(0)
        )
    dropped = sum(1 for row in rows if row["GenEdge"] not in badhersfeld.edge_index)
    assert dropped > 0 and f"{dropped} of 11270 buildings" in caplog.text
    mass: dict[int, float] = defaultdict(float)
    for position, weight in zip(dist.positions, dist.weights, strict=True):
        mass[position.edge] += float(weight)
        assert 0.0 <= position.offset <= badhersfeld.length[position.edge]
    assert {badhersfeld.edge_ids[e] for e in mass} == set(kept)
    for edge_id, weight in kept.items():
        assert mass[badhersfeld.edge_index[edge_id]] == pytest.approx(weight / total, rel=1e-9)


def test_buildings_off_the_network_are_refused(
    badhersfeld: CompiledNetwork, tmp_path: Path
) -> None:
    path = tmp_path / "elsewhere.csv"
    path.write_text("TAZ,Poly,Area,Weight,GenEdge,PedEdge\nall,1,10,1.0,nowhere,nowhere\n")
    with pytest.raises(InvalidInput, match="none of its 1 buildings"):
        network_demand(
            badhersfeld, parse_demand_spec(f"buildings:{path}"), rng=np.random.default_rng(0)
        )
    path.write_text("TAZ,Area\nall,1\n")
    with pytest.raises(InvalidInput, match="'Weight' and 'GenEdge'"):
        network_demand(
            badhersfeld, parse_demand_spec(f"buildings:{path}"), rng=np.random.default_rng(0)
        )


def test_person_requests_follow_the_profile(badhersfeld: CompiledNetwork) -> None:
    """Requests per hour under a profile: rate x 24 w_h / sum(w) (thinning a Poisson stream)."""
    uniform = network_demand(
        badhersfeld, parse_demand_spec("uniform"), rng=np.random.default_rng(0)
    )
    requests = person_requests(
        badhersfeld,
        [Phase(0.0, uniform)],
        Destinations(badhersfeld, uniform, radius=1000.0),
        rng=np.random.default_rng(1),
        rate_per_hour=120.0,
        start=0.0,
        end=86400.0,
        profile=HourlyProfile((1.0,) * 12 + (3.0,) * 12),
    )
    morning = sum(1 for r in requests if r.time < 43200.0)
    # expected 120 * 0.5 * 12 = 720 before noon and 120 * 1.5 * 12 = 2160 after: 5 sigma
    assert abs(morning - 720) < 5 * 27 and abs(len(requests) - morning - 2160) < 5 * 47
