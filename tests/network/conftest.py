"""Networks for the road-network tests: two real OSM districts and generated nets.

- ``drt``: ``<SUMO_HOME>/tools/game/DRT/osm.net.xml`` from the eclipse-sumo
  package (Berlin, converted from OpenStreetMap, with a UTM projection);
- ``bs3d``: ``<SUMO_HOME>/tools/game/bs3d/bs.net.xml``, a part of Braunschweig
  converted from OpenStreetMap that eclipse-sumo ships (42 of its 174 passenger edges
  are one-way);
- ``oneway``: generated here with ``netgenerate --rand`` where only 60 % of
  the roads are two-way and no U-turns exist, so many targets can only be
  reached by driving around a block, and many edges fall outside the largest
  strongly connected component;
- ``grid``: a 10 x 10 ``netgenerate --grid`` where every turn (U-turns
  included) is allowed, so all edges into a junction share one end state;
- ``restricted``: that grid with 15 % of its connections deleted by
  ``netconvert`` (turn restrictions), so edges into one junction often differ;
"""

from __future__ import annotations

import subprocess
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import sumo

from routing_svc.network import CompiledNetwork, RoadSpace, load_network
from routing_svc.types import NetPosition
from tests.network.reference import NxReference

SUMO_HOME = Path(sumo.SUMO_HOME)
DRT_NET = SUMO_HOME / "tools" / "game" / "DRT" / "osm.net.xml"
BS3D_NET = SUMO_HOME / "tools" / "game" / "bs3d" / "bs.net.xml"
ONEWAY_ARGS = (
    "--rand",
    "--rand.iterations=400",
    "--seed=3",
    "--bidi-probability=0.6",
    "--rand.random-lanenumber=false",
    "--default.lanenumber=1",
    "--no-turnarounds",
)


GRID_ARGS = ("--grid", "--grid.number=10", "--grid.length=100")
RESTRICTED_SHARE = 0.15


@dataclass(frozen=True)
class NetCase:
    """A compiled network, the file it came from, and its networkx reference."""

    name: str
    path: Path
    network: CompiledNetwork
    reference: NxReference

    def random_positions(self, rng: np.random.Generator, n: int) -> list[NetPosition]:
        edges = rng.integers(self.network.n_edges, size=n)
        return [NetPosition(int(e), float(rng.uniform(0.0, self.network.length[e]))) for e in edges]

    def ids(self, position: NetPosition) -> tuple[str, float]:
        return self.network.edge_ids[position.edge], position.offset


def _netgenerate(path: Path, args: Sequence[str]) -> Path:
    """Run SUMO's netgenerate with ``args``, writing ``path``."""
    subprocess.run(
        [str(SUMO_HOME / "bin" / "netgenerate"), *args, "--output-file", str(path)],
        check=True,
        capture_output=True,
    )
    return path


def generate_oneway_net(folder: Path) -> Path:
    """A one-way-heavy random network made with SUMO's netgenerate."""
    return _netgenerate(folder / "oneway.net.xml", ONEWAY_ARGS)


def generate_grid_net(folder: Path) -> Path:
    """A 10 x 10 junction grid with every turn allowed, made with SUMO's netgenerate."""
    return _netgenerate(folder / "grid.net.xml", GRID_ARGS)


def generate_restricted_net(folder: Path) -> Path:
    """The grid with a fixed random 15 % of its connections deleted (turn restrictions)."""
    import sumolib

    grid = generate_grid_net(folder)
    net = sumolib.net.readNet(str(grid), withConnections=True)
    rng = np.random.default_rng(5)
    deletions = [
        f'<delete from="{edge.getID()}" to="{to_edge.getID()}"/>'
        for edge in net.getEdges()
        for to_edge in edge.getOutgoing()
        if rng.random() < RESTRICTED_SHARE
    ]
    connections = folder / "restrictions.con.xml"
    connections.write_text("<connections>\n" + "\n".join(deletions) + "\n</connections>\n")
    path = folder / "restricted.net.xml"
    subprocess.run(
        [
            str(SUMO_HOME / "bin" / "netconvert"),
            "--sumo-net-file",
            str(grid),
            "--connection-files",
            str(connections),
            "--output-file",
            str(path),
        ],
        check=True,
        capture_output=True,
    )
    return path


@pytest.fixture(scope="session")
def network_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("compiled")


@pytest.fixture(scope="session")
def oneway_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return generate_oneway_net(tmp_path_factory.mktemp("oneway"))


@pytest.fixture(scope="session")
def drt_case(network_cache: Path) -> NetCase:
    network = load_network(DRT_NET, cache_dir=network_cache)
    return NetCase("drt", DRT_NET, network, NxReference(DRT_NET))


@pytest.fixture(scope="session")
def bs3d_case(network_cache: Path) -> NetCase:
    network = load_network(BS3D_NET, cache_dir=network_cache)
    return NetCase("bs3d", BS3D_NET, network, NxReference(BS3D_NET))


@pytest.fixture(scope="session")
def oneway_case(network_cache: Path, oneway_path: Path) -> NetCase:
    network = load_network(oneway_path, cache_dir=network_cache)
    return NetCase("oneway", oneway_path, network, NxReference(oneway_path))


@pytest.fixture(scope="session")
def grid_case(network_cache: Path, tmp_path_factory: pytest.TempPathFactory) -> NetCase:
    path = generate_grid_net(tmp_path_factory.mktemp("grid"))
    return NetCase("grid", path, load_network(path, cache_dir=network_cache), NxReference(path))


@pytest.fixture(scope="session")
def restricted_case(network_cache: Path, tmp_path_factory: pytest.TempPathFactory) -> NetCase:
    path = generate_restricted_net(tmp_path_factory.mktemp("restricted"))
    return NetCase(
        "restricted", path, load_network(path, cache_dir=network_cache), NxReference(path)
    )


@pytest.fixture(scope="session", params=["drt", "bs3d", "oneway"])
def case(request: pytest.FixtureRequest) -> NetCase:
    """Each test network in turn."""
    result: NetCase = request.getfixturevalue(f"{request.param}_case")
    return result


@pytest.fixture
def space(case: NetCase) -> RoadSpace:
    return RoadSpace(case.network, either_way=False)
