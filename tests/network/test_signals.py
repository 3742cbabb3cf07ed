"""Links a traffic light never lets pass, against SUMO running the network's lights.

The reference runs SUMO (libsumo) on the empty network for a whole cycle of
every light and records, per link index, whether it ever showed ``G`` or ``g``;
links are mapped to edges through SUMO's ``getControlledLinks``.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import libsumo
import pytest

from routing_svc.network import load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.network.signals import audit_signals
from routing_svc.network.sumo_tools import sumo_tool

Pairs = set[tuple[str, str]]


def _edge(lane: str) -> str:
    return lane.rpartition("_")[0]


def blocked_by_sumo(net: Path, edges: set[str]) -> tuple[Pairs, Pairs]:
    """``(links, never green)`` as edge pairs, watched in SUMO for one cycle of every light."""
    libsumo.start(["sumo", "-n", str(net), "--no-step-log", "--no-warnings"])
    try:
        lights = list(libsumo.trafficlight.getIDList())
        cycle = 0.0
        for light in lights:
            program = libsumo.trafficlight.getProgram(light)
            logic = next(
                p for p in libsumo.trafficlight.getAllProgramLogics(light)
                if p.programID == program
            )  # fmt: skip
            cycle = max(cycle, sum(phase.duration for phase in logic.phases))
        green: dict[str, set[int]] = {light: set() for light in lights}
        for _ in range(int(cycle) + 2):
            for light in lights:
                state = libsumo.trafficlight.getRedYellowGreenState(light)
                green[light].update(i for i, s in enumerate(state) if s in "Gg")
            libsumo.simulationStep()
        links: dict[tuple[str, str], bool] = {}
        for light in lights:
            for index, controlled in enumerate(libsumo.trafficlight.getControlledLinks(light)):
                for incoming, outgoing, _ in controlled:
                    pair = (_edge(incoming), _edge(outgoing))
                    if pair[0] in edges and pair[1] in edges:
                        links[pair] = links.get(pair, False) or index in green[light]
    finally:
        libsumo.close()
    return set(links), {pair for pair, passes in links.items() if not passes}


@pytest.fixture(scope="module")
def bs3d() -> Path:
    return resolve_network("bs3d")


@pytest.fixture(scope="module")
def bs3d_rebuilt(bs3d: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("signals") / "bs3d_rebuilt.net.xml"
    netconvert, env = sumo_tool("netconvert")
    subprocess.run(
        [netconvert, "-s", str(bs3d), "--tls.rebuild", "-o", str(out), "--no-warnings"],
        check=True,
        capture_output=True,
        env=env,
    )
    return out


def _pairs(names: tuple[str, ...]) -> Pairs:
    pairs = set()
    for name in names:
        origin, destination = name.split(": ", 1)[1].split(" -> ")
        pairs.add((origin, destination))
    return pairs


@pytest.mark.parametrize("name", ["bs3d", "bs3d_rebuilt", "drt"])
def test_never_green_links_are_those_sumo_never_shows_green(
    name: str, request: pytest.FixtureRequest
) -> None:
    net = request.getfixturevalue(name) if name != "drt" else resolve_network("drt")
    network = load_network(net)
    audit = audit_signals(net, network)
    links, never = blocked_by_sumo(net, set(network.edge_ids))
    assert audit.links == len(links)
    assert _pairs(audit.never_green) == never
    assert len(audit.never_green) == len(never)


def test_the_game_network_blocks_most_links_of_its_light_and_rebuilt_programs_none(
    bs3d: Path, bs3d_rebuilt: Path
) -> None:
    game = audit_signals(bs3d, load_network(bs3d))
    assert game.signals == 1
    assert game.longest_phase == 1000.0
    assert len(game.never_green) > game.links / 2
    warning = game.warning("bs3d")
    assert warning is not None and f"{len(game.never_green)} of the {game.links}" in warning
    rebuilt = audit_signals(bs3d_rebuilt, load_network(bs3d_rebuilt))
    assert rebuilt.links == game.links
    assert rebuilt.never_green == ()
    assert rebuilt.warning("rebuilt") is None
    assert rebuilt.to_dict()["never_green"] == 0


def test_a_network_without_lights_has_nothing_to_report(tmp_path: Path) -> None:
    net = resolve_network("grid", out_dir=tmp_path)
    audit = audit_signals(net, load_network(net))
    assert audit.to_dict() == {
        "signals": 0,
        "links": 0,
        "never_green": 0,
        "never_green_links": [],
        "longest_phase_s": 0.0,
    }
