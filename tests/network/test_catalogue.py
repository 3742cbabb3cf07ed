"""Generated and shipped road networks: shape, determinism, name resolution, CLI."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
import sumolib

from routing_svc.errors import InvalidInput, InvalidNetwork, UnknownNetwork
from routing_svc.network import load_network
from routing_svc.network.catalogue import (
    GENERATED,
    add_parser,
    cache_dir,
    generate_network,
    list_networks,
    named_network,
    resolve_network,
    run,
)
from routing_svc.network.sumo_tools import sumo_home


@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("nets")
    return {name: generate_network(name, out_dir=folder) for name in GENERATED}


def road_graph(path: Path) -> tuple[nx.DiGraph, list[tuple[str, str]]]:
    net = sumolib.net.readNet(str(path))
    pairs = [(e.getFromNode().getID(), e.getToNode().getID()) for e in net.getEdges(False)]
    graph = nx.DiGraph()
    graph.add_edges_from(pairs)
    return graph, pairs


@pytest.mark.parametrize(
    ("name", "junctions", "edges", "one_way"),
    [("grid", 36, 120, 0), ("spider", 41, 160, 0), ("oneway", 64, 140, 84)],
)
def test_generated_network_shape(
    generated: dict[str, Path], name: str, junctions: int, edges: int, one_way: int
) -> None:
    graph, pairs = road_graph(generated[name])
    assert graph.number_of_nodes() == junctions
    assert len(pairs) == edges
    present = set(pairs)
    assert sum((b, a) not in present for a, b in pairs) == one_way
    assert nx.is_strongly_connected(graph)


def test_oneway_is_mostly_one_way(generated: dict[str, Path]) -> None:
    graph, pairs = road_graph(generated["oneway"])
    present = set(pairs)
    assert sum((b, a) not in present for a, b in pairs) > len(pairs) / 2
    lengths = dict(nx.all_pairs_dijkstra_path_length(graph))
    assert any(lengths[a][b] != lengths[b][a] for a in graph for b in graph)


def test_generation_is_deterministic(generated: dict[str, Path], tmp_path: Path) -> None:
    for name, first in generated.items():
        again = generate_network(name, out_dir=tmp_path)
        assert again.read_bytes() == first.read_bytes(), name
        assert b"generated on" not in again.read_bytes()[:500]


def test_existing_file_is_kept_unless_forced(tmp_path: Path) -> None:
    path = generate_network("grid", out_dir=tmp_path)
    original = path.read_bytes()
    path.write_bytes(b"<net/>")
    assert generate_network("grid", out_dir=tmp_path).read_bytes() == b"<net/>"
    assert generate_network("grid", out_dir=tmp_path, force=True).read_bytes() == original
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grid.net.xml"]  # no scratch left


def test_cache_dir_follows_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROUTING_SVC_CACHE", str(tmp_path / "cache"))
    assert cache_dir() == tmp_path / "cache" / "nets"
    [grid] = [n for n in list_networks() if n.name == "grid"]
    assert (grid.source, grid.exists) == ("generated", False)
    path = resolve_network("grid")
    assert path == tmp_path / "cache" / "nets" / "grid.net.xml" and path.is_file()
    [grid] = [n for n in list_networks() if n.name == "grid"]
    assert grid.exists


def test_shipped_networks_are_listed_in_place(tmp_path: Path) -> None:
    home = sumo_home()
    assert home is not None
    nets = {n.name: n for n in list_networks(out_dir=tmp_path)}
    assert {"grid", "spider", "oneway", "drt"} <= set(nets)
    drt = nets["drt"]
    assert drt.source == "eclipse-sumo" and drt.exists
    assert drt.path == home / "tools" / "game" / "DRT" / "osm.net.xml"
    shipped = [n for n in nets.values() if n.source == "eclipse-sumo"]
    assert len(shipped) >= 4
    assert all(n.path.is_file() and n.path.is_relative_to(home) for n in shipped)
    assert resolve_network("drt", out_dir=tmp_path) == drt.path


def test_every_shipped_network_is_a_loop_for_cars_or_refused_with_the_reason(
    tmp_path: Path,
) -> None:
    """What a user gets from each of SUMO's networks known by name: a compiled network in
    which every edge reaches every other (networkx on its arcs), or a refusal that says
    whether no edge is open to cars or no loop of them is."""
    shipped = [n for n in list_networks(out_dir=tmp_path) if n.source == "eclipse-sumo"]
    verdicts = {}
    for net in shipped:
        try:
            compiled = load_network(net.path, cache_dir=tmp_path / "cache")
        except InvalidNetwork as refused:
            edges = sumolib.net.readNet(str(net.path)).getEdges(False)
            open_to_cars = [e for e in edges if e.allows("passenger")]
            reason = "no edge open" if not open_to_cars else "no loop of edges open"
            assert reason in str(refused), (net.name, str(refused))
            verdicts[net.name] = reason
            continue
        graph = nx.DiGraph()
        graph.add_nodes_from(range(compiled.n_edges))
        tails = np.repeat(np.arange(compiled.n_edges), np.diff(compiled.fwd_indptr))
        graph.add_edges_from(zip(tails.tolist(), compiled.fwd_indices.tolist(), strict=True))
        assert nx.is_strongly_connected(graph), net.name
        assert compiled.n_edges > 1 or graph.has_edge(0, 0), net.name
        verdicts[net.name] = "compiled"
    assert verdicts["drt"] == "compiled" and verdicts["bs3d"] == "compiled"
    assert verdicts["corridor"] == "no loop of edges open"  # one way through, no way back
    assert "compiled" in verdicts.values() and len(set(verdicts.values())) >= 2


def test_resolve_network(tmp_path: Path) -> None:
    own = tmp_path / "mine.net.xml"
    own.write_text("<net/>")
    assert resolve_network(own, out_dir=tmp_path) == own
    assert resolve_network(str(own), out_dir=tmp_path) == own
    with pytest.raises(UnknownNetwork, match="neither a known network"):
        resolve_network("atlantis", out_dir=tmp_path)
    with pytest.raises(UnknownNetwork):
        resolve_network(tmp_path / "missing.net.xml", out_dir=tmp_path)
    with pytest.raises(UnknownNetwork):
        resolve_network(tmp_path, out_dir=tmp_path)  # a folder is not a network
    with pytest.raises(UnknownNetwork):
        generate_network("drt", out_dir=tmp_path)  # shipped, not generated


def test_named_network_splits_name_and_path() -> None:
    assert named_network("town=/data/town.net.xml.gz") == ("town", "/data/town.net.xml.gz")
    assert named_network("drt") == ("drt", "drt")  # a bare name is its own path
    assert named_network("a=b=c") == ("a", "b=c")  # only the first '=' splits
    for bad in ("", "=town.net.xml", "town="):
        with pytest.raises(InvalidInput, match="NAME=PATH or NAME"):
            named_network(bad)


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="routing-svc")
    add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(argv)


def test_cli_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = parse(["nets", "--json", "--generate", "--cache-dir", str(tmp_path)])
    assert args.run is run
    assert run(args) == 0
    rows = json.loads(capsys.readouterr().out)
    by_name = {row["name"]: row for row in rows}
    assert all(by_name[name]["exists"] for name in GENERATED)
    assert by_name["oneway"]["path"] == str(tmp_path / "oneway.net.xml")
    assert by_name["drt"]["source"] == "eclipse-sumo"


def test_cli_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run(parse(["nets", "--cache-dir", str(tmp_path)])) == 0
    out = capsys.readouterr().out
    assert "oneway" in out and "drt" in out and "eclipse-sumo" in out
