"""Demand distributions: validation, exact JSON round trip, sampling, constructors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import sumo

from routing_svc.demand import (
    DemandDistribution,
    from_weights_file,
    gaussian_mixture,
    hotspot_mixture,
    uniform_by_length,
    uniform_rectangle,
)
from routing_svc.errors import InvalidInput, PayloadTooLarge
from routing_svc.network import CompiledNetwork, RoadSpace, load_network
from routing_svc.types import NetPosition, PlanePosition

DRT_NET = Path(sumo.SUMO_HOME) / "tools" / "game" / "DRT" / "osm.net.xml"


@pytest.fixture(scope="module")
def drt(tmp_path_factory: pytest.TempPathFactory) -> CompiledNetwork:
    return load_network(DRT_NET, cache_dir=tmp_path_factory.mktemp("demand-cache"))


def gaussian(x: float, y: float, centre: tuple[float, float], spread: float) -> float:
    d2 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2
    return math.exp(-d2 / (2 * spread**2)) / (2 * math.pi * spread**2)


# --- the distribution itself -------------------------------------------------------


def test_from_masses_normalises_and_drops_zero_mass() -> None:
    pts = [PlanePosition(0.0, 0.0), PlanePosition(1.0, 0.0), PlanePosition(2.0, 0.0)]
    d = DemandDistribution.from_masses("x", pts, [3.0, 0.0, 1.0])
    assert d.positions == (pts[0], pts[2])
    assert d.weights.tolist() == [0.75, 0.25]
    assert d.kind == "plane" and len(d) == 2
    with pytest.raises(ValueError):
        d.weights[0] = 1.0  # read-only


@pytest.mark.parametrize(
    ("positions", "weights", "message"),
    [
        ([], [], "at least one atom"),
        ([PlanePosition(0.0, 0.0)], [0.5, 0.5], "weights of shape"),
        ([PlanePosition(0.0, 0.0)], [0.9], "sum to 1"),
        ([PlanePosition(0.0, 0.0), PlanePosition(1.0, 1.0)], [1.5, -0.5], ">= 0"),
        ([PlanePosition(0.0, 0.0)], [math.nan], "finite"),
        ([PlanePosition(0.0, math.inf)], [1.0], "finite"),
        ([PlanePosition(0.0, 0.0), NetPosition(0, 0.0)], [0.5, 0.5], "all be NetPosition"),
        ([NetPosition(0, -1.0)], [1.0], ">= 0"),
    ],
)
def test_invalid_distributions_are_rejected(
    positions: list[PlanePosition], weights: list[float], message: str
) -> None:
    with pytest.raises(InvalidInput, match=message):
        DemandDistribution("bad", tuple(positions), np.array(weights))


def test_json_round_trip_is_exact() -> None:
    rng = np.random.default_rng(0)
    masses = rng.random(50) ** 3
    plane = DemandDistribution.from_masses(
        "p", [PlanePosition(float(x), float(y)) for x, y in rng.normal(size=(50, 2))], masses
    )
    net = DemandDistribution.from_masses(
        "n", [NetPosition(e, float(s)) for e, s in enumerate(rng.random(50) * 99)], masses
    )
    for original in (plane, net):
        copy = DemandDistribution.from_json(original.to_json())
        assert copy.name == original.name and copy.kind == original.kind
        assert copy.positions == original.positions
        assert copy.weights.tobytes() == original.weights.tobytes()
        assert type(copy.positions[0]) is type(original.positions[0])


@pytest.mark.parametrize(
    "text",
    [
        "not json",
        "[]",
        json.dumps({"format": "other"}),
        json.dumps({"format": "routing_svc.demand/1", "name": "x", "kind": "sphere",
                    "positions": [[0, 0]], "weights": [1.0]}),
        json.dumps({"format": "routing_svc.demand/1", "name": "x", "kind": "network",
                    "positions": [[0.5, 0]], "weights": [1.0]}),
        json.dumps({"format": "routing_svc.demand/1", "name": "x", "kind": "plane",
                    "positions": [[0, 0]], "weights": [True]}),
        json.dumps({"format": "routing_svc.demand/1", "name": "x", "kind": "plane",
                    "positions": [[0, 0, 0]], "weights": [1.0]}),
    ],
)  # fmt: skip
def test_bad_json_is_rejected(text: str) -> None:
    with pytest.raises(InvalidInput):
        DemandDistribution.from_json(text)


def test_sampling_follows_the_weights_and_the_seed() -> None:
    pts = [PlanePosition(float(i), 0.0) for i in range(4)]
    d = DemandDistribution.from_masses("s", pts, [0.1, 0.2, 0.3, 0.4])
    draws = d.sample(np.random.default_rng(1), 40_000)
    counts = np.array([sum(1 for p in draws if p == q) for q in pts])
    expected = d.weights * 40_000
    assert np.all(np.abs(counts - expected) < 5 * np.sqrt(expected))  # about 5 sigma
    again = d.sample(np.random.default_rng(1), 40_000)
    assert again == draws
    assert d.sample(np.random.default_rng(1), 0) == []
    with pytest.raises(InvalidInput):
        d.sample(np.random.default_rng(1), -1)


# --- the plane ---------------------------------------------------------------------


def test_uniform_rectangle_is_a_centred_grid() -> None:
    d = uniform_rectangle((0.0, 0.0, 4.0, 2.0), cells=4)
    assert len(d) == 16
    assert np.all(d.weights == 1 / 16)
    xs = sorted({p.x for p in d.positions})
    ys = sorted({p.y for p in d.positions})
    assert xs == [0.5, 1.5, 2.5, 3.5] and ys == [0.25, 0.75, 1.25, 1.75]
    with pytest.raises(InvalidInput):
        uniform_rectangle((1.0, 0.0, 0.0, 1.0))
    with pytest.raises(InvalidInput):
        uniform_rectangle((0.0, 0.0, 1.0, 1.0), cells=0)


def test_gaussian_mixture_weights_follow_the_density() -> None:
    centres = [(2.0, 3.0), (7.0, 6.0)]
    d = gaussian_mixture(
        (0.0, 0.0, 10.0, 10.0), centres=centres, spread=1.2, weights=[1.0, 3.0], cells=15
    )
    density = [
        0.25 * gaussian(p.x, p.y, centres[0], 1.2) + 0.75 * gaussian(p.x, p.y, centres[1], 1.2)
        for p in d.positions
    ]
    np.testing.assert_allclose(d.weights, np.array(density) / sum(density), rtol=1e-12)
    with pytest.raises(InvalidInput, match="spread"):
        gaussian_mixture((0.0, 0.0, 1.0, 1.0), centres=centres, spread=0.0)
    with pytest.raises(InvalidInput, match="weights"):
        gaussian_mixture((0.0, 0.0, 1.0, 1.0), centres=centres, spread=1.0, weights=[1.0])


# --- the road network --------------------------------------------------------------


def test_uniform_by_length_covers_every_edge_in_pieces(drt: CompiledNetwork) -> None:
    d = uniform_by_length(drt)
    assert d.kind == "network" and len(d) <= 3000
    total = float(drt.length.sum())
    per_edge = np.zeros(drt.n_edges)
    count = np.zeros(drt.n_edges, dtype=int)
    for p, w in zip(d.positions, d.weights, strict=True):
        assert 0.0 < p.offset < drt.length[p.edge]
        per_edge[p.edge] += w
        count[p.edge] += 1
    np.testing.assert_allclose(per_edge, drt.length / total, rtol=1e-9)
    assert np.all(drt.length / count <= 20.0 + 1e-9)
    assert np.all(drt.length / np.maximum(count - 1, 1e-9) > 20.0)  # no more pieces than needed
    coarse = uniform_by_length(drt, spacing=1e6)
    assert len(coarse) == drt.n_edges
    assert {p.offset for p in coarse.positions} == {float(x) / 2 for x in drt.length}
    with pytest.raises(InvalidInput, match="spacing"):
        uniform_by_length(drt, spacing=0.0)


def test_hotspot_weights_are_length_times_density(drt: CompiledNetwork) -> None:
    uniform = uniform_by_length(drt, spacing=50.0)
    centres = [(800.0, 600.0), (1600.0, 1100.0)]
    d = hotspot_mixture(drt, centres=centres, spread=200.0, spacing=50.0)
    space = RoadSpace(drt)
    assert d.positions == uniform.positions  # no atom has zero density here
    mass = [
        float(w) * sum(gaussian(*space.xy(p), c, 200.0) for c in centres)
        for p, w in zip(uniform.positions, uniform.weights, strict=True)
    ]
    np.testing.assert_allclose(d.weights, np.array(mass) / sum(mass), rtol=1e-9)


def test_drawn_hotspots_depend_only_on_the_seed(drt: CompiledNetwork) -> None:
    a = hotspot_mixture(drt, centres=3, rng=np.random.default_rng(7))
    b = hotspot_mixture(drt, centres=3, rng=np.random.default_rng(7))
    c = hotspot_mixture(drt, centres=3, rng=np.random.default_rng(8))
    assert a.name == "hotspots:3"
    assert a.weights.tobytes() == b.weights.tobytes()
    assert a.weights.tobytes() != c.weights.tobytes()
    with pytest.raises(InvalidInput, match="rng"):
        hotspot_mixture(drt, centres=3)
    with pytest.raises(InvalidInput, match="between 1"):
        hotspot_mixture(drt, centres=0, rng=np.random.default_rng(7))


def test_weights_file_csv_and_json_agree(drt: CompiledNetwork, tmp_path: Path) -> None:
    ids = drt.edge_ids
    csv_path = tmp_path / "w.csv"
    csv_path.write_text(f'# demand\nedge_id,weight\n\n{ids[0]},3\n"{ids[5]}",1.0\n{ids[9]},0\n')
    json_path = tmp_path / "w.json"
    json_path.write_text(json.dumps({ids[0]: 3, ids[5]: 1.0, ids[9]: 0}))
    a = from_weights_file(drt, csv_path)
    b = from_weights_file(drt, json_path)
    assert a.positions == b.positions and a.weights.tobytes() == b.weights.tobytes()
    per_edge: dict[int, float] = {}
    for p, w in zip(a.positions, a.weights, strict=True):
        per_edge[p.edge] = per_edge.get(p.edge, 0.0) + float(w)
    assert set(per_edge) == {0, 5}
    assert per_edge[0] == pytest.approx(0.75) and per_edge[5] == pytest.approx(0.25)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("edge,weight\n{e0},1\nnope,2\n", "w.csv line 3: unknown edge 'nope'"),
        ("{e0},1\n{e0},2\n", "w.csv line 2: edge .* listed twice"),
        ("{e0},-1\n", "w.csv line 1: weight must be a finite number >= 0"),
        ("{e0},nan\n", "w.csv line 1: weight must be a finite number"),
        ("{e0},1\n{e1},heavy\n", "w.csv line 2: weight 'heavy' is not a number"),
        ("{e0},heavy\n", "w.csv line 1: weight 'heavy' is not a number"),
        ("{e0},1,2\n", "w.csv line 1: expected 'edge_id,weight'"),
        (":J1_0,1\n", "internal junction edge"),
        ("{e0},0\n", "no edge has a positive weight"),
        ("", "no edge has a positive weight"),
    ],
)
def test_bad_csv_files_name_the_line(
    drt: CompiledNetwork, tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "w.csv"
    path.write_text(text.format(e0=drt.edge_ids[0], e1=drt.edge_ids[1]))
    with pytest.raises(InvalidInput, match=message):
        from_weights_file(drt, path)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('{\n  "a": 1,\n  "b": \n}', "w.json line 4: malformed JSON"),
        ('{"nope": 1}', "w.json key 'nope': unknown edge"),
        ('{"E0": "1"}', "weight must be a number"),
        ('{"E0": NaN}', "NaN"),
        ('{"E0": 1, "E0": 2}', "listed twice"),
    ],
)
def test_bad_json_files_name_the_place(
    drt: CompiledNetwork, tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "w.json"
    path.write_text(text.replace("E0", drt.edge_ids[0]))
    with pytest.raises(InvalidInput, match=message):
        from_weights_file(drt, path)


def test_missing_and_oversized_files(drt: CompiledNetwork, tmp_path: Path) -> None:
    with pytest.raises(InvalidInput, match="does not exist"):
        from_weights_file(drt, tmp_path / "none.csv")
    from routing_svc.demand.weights_file import read_edge_weights

    big = tmp_path / "big.csv"
    big.write_text(f"{drt.edge_ids[0]},1\n" * 100)
    with pytest.raises(PayloadTooLarge):
        read_edge_weights(big, known_edges=drt.edge_index, max_bytes=50)


def test_of_targets_weighs_each_distinct_target_by_its_count() -> None:
    a, b, c = NetPosition(0, 1.0), NetPosition(2, 0.5), NetPosition(1, 3.0)
    demand = DemandDistribution.of_targets("s", [b, a, b, c, b, a])
    assert demand.positions == (b, a, c)  # the order of first occurrence
    np.testing.assert_array_equal(demand.weights, [3 / 6, 2 / 6, 1 / 6])
    with pytest.raises(InvalidInput):
        DemandDistribution.of_targets("empty", [])
