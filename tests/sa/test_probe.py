"""The backward probe on a directed network (``FleetConfig.probe``), on a hand-made net.

The net is two one-way loops through one junction ``j1``: ``a`` (``j0 -> j1``)
turns into ``b`` (``j1 -> j2``) or ``c`` (``j1 -> j3``), and ``d`` (``j2 -> j0``)
and ``e`` (``j3 -> j0``) lead back to ``a``. Every edge is 100 m long, one-way,
and there are no U-turns, so a reference just past ``j1`` on ``b`` reaches
``c`` only around the loop ``b, d, a``: ``J`` jumps by that loop at ``j1``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork, RoadSpace, load_network
from routing_svc.sa import (
    ROUTING,
    Annealing,
    Constant,
    EuclideanPlane,
    Fleet,
    FleetConfig,
    InverseScaling,
    Vehicle,
)
from routing_svc.sa.space import DirectedSpace, Requirement
from routing_svc.types import NetPosition, PlanePosition
from tests.sa.conftest import hand_made_net_xml

_XY = {"j0": (0.0, 0.0), "j1": (100.0, 0.0), "j2": (150.0, 80.0), "j3": (150.0, -80.0)}
_EDGES = {"a": ("j0", "j1"), "b": ("j1", "j2"), "c": ("j1", "j3"), "d": ("j2", "j0")}
_EDGES["e"] = ("j3", "j0")
_TURNS = [("a", "b"), ("a", "c"), ("b", "d"), ("c", "e"), ("d", "a"), ("e", "a")]


def _net_xml() -> str:
    return hand_made_net_xml(_XY, {e: (a, b, 100.0) for e, (a, b) in _EDGES.items()}, _TURNS)


@pytest.fixture(scope="module")
def network(tmp_path_factory: pytest.TempPathFactory) -> CompiledNetwork:
    folder: Path = tmp_path_factory.mktemp("probe_net")
    path = folder / "loops.net.xml"
    path.write_text(_net_xml())
    return load_network(path, cache_dir=folder / "cache")


@pytest.fixture(scope="module")
def space(network: CompiledNetwork) -> RoadSpace:
    return RoadSpace(network, cost="length")


def at(network: CompiledNetwork, edge: str, offset: float) -> NetPosition:
    return NetPosition(network.edge_ids.index(edge), offset)


def fleet_of(
    space: RoadSpace, positions: list[NetPosition], *, probe: float | None, gamma: float
) -> Fleet[NetPosition]:
    config = FleetConfig(objective=ROUTING, schedule=Constant(gamma), probe=probe)
    vehicles = [(Vehicle(f"v{i}"), p) for i, p in enumerate(positions)]
    return Fleet.create(space, vehicles, config)


def test_the_net_is_the_one_described(network: CompiledNetwork, space: RoadSpace) -> None:
    assert sorted(network.edge_ids) == ["a", "b", "c", "d", "e"]
    assert np.all(network.length == 100.0)
    assert isinstance(space, DirectedSpace)
    # Just past j1 on b, c is reached only around the loop b, d, a.
    assert space.path_cost(at(network, "b", 5.0), at(network, "c", 50.0)) == 345.0
    assert space.path_cost(at(network, "a", 100.0), at(network, "c", 50.0)) == 50.0


def test_step_across_a_junction_records_the_turns_given_up(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    fleet = fleet_of(space, [at(network, "a", 95.0)], probe=10.0, gamma=10.0)
    out = fleet.observe(at(network, "b", 50.0))  # its probe (a, 85) gains nothing
    assert out.moved_by == 10.0
    assert fleet.state.positions == [at(network, "b", 5.0)]
    assert fleet.state.entries == [at(network, "a", 100.0)]
    # Forward on b the entry is kept, and it is the probe while within the window.
    fleet.observe(at(network, "b", 50.0))
    assert fleet.state.positions == [at(network, "b", 15.0)]
    assert fleet.state.entries == [at(network, "a", 100.0)]
    assert space.back_probes(
        [at(network, "b", 5.0), at(network, "b", 15.0), at(network, "c", 3.0)],
        10.0,
        [at(network, "a", 100.0), None, None],
    ) == [at(network, "a", 100.0), at(network, "b", 5.0), at(network, "c", 0.0)]
    with pytest.raises(InvalidInput):
        space.back_probes([NetPosition(0, 1e9)], 10.0, [None])


@pytest.mark.parametrize(
    ("gamma", "expected"),
    [
        # gain G = 345 - 50 = 295 behind the entry, window h = 10:
        # gamma G / h = 29.5 >= h, so the move is capped at h, past the 5 m back to j1.
        (1.0, ("a", 100.0)),
        # gamma G / h = 0.1 * 295 / 10 = 2.95 < 5: back along b.
        (0.1, ("b", 5.0 - 2.95)),
    ],
)
def test_hand_computed_probe_step_through_the_entry(
    network: CompiledNetwork, space: RoadSpace, gamma: float, expected: tuple[str, float]
) -> None:
    fleet = fleet_of(space, [at(network, "b", 5.0)], probe=10.0, gamma=gamma)
    fleet.state.entries = [at(network, "a", 100.0)]
    out = fleet.observe(at(network, "c", 50.0))
    assert out.dispatch.cost == 345.0
    assert out.moved_by == 0.0  # the probe moved the mover: no forward step
    assert fleet.state.positions[0] == pytest.approx(at(network, *expected), abs=1e-12)
    assert fleet.state.positions[0].edge == at(network, *expected).edge
    assert out.old_position == at(network, "b", 5.0)
    assert out.new_position == fleet.state.positions[0]
    assert out.backed_off == ((0, fleet.state.positions[0]),)
    # Back on the entry, where it entered is unknown; back along b, it is kept.
    entry = None if expected[0] == "a" else at(network, "a", 100.0)
    assert fleet.state.entries == [entry]


def test_hand_computed_probe_step_on_its_own_edge(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    # At (b, 30) the probe is (b, 20); the target (b, 25) just passed costs the loop
    # 70 + 100 + 100 + 25 = 295 from the reference and 5 from the probe: G = 290,
    # and the step back is gamma G / h = 0.1 * 290 / 10 = 2.9.
    fleet = fleet_of(space, [at(network, "b", 30.0)], probe=10.0, gamma=0.1)
    out = fleet.observe(at(network, "b", 25.0))
    assert out.dispatch.cost == 295.0
    assert fleet.state.positions[0].edge == at(network, "b", 0.0).edge
    assert fleet.state.positions[0].offset == pytest.approx(27.1, abs=1e-12)


def test_probe_moves_every_vehicle_whose_probe_beats_the_fleet(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    # v0 serves (c, 50) from (e, 0) in 100 + 100 + 50 = 250; its probe is itself
    # (no entry, offset 0). v1 and v2, just past j1, probe j1 (their entry), 50
    # from the target: each gains G = 200 and backs off gamma G / h = 2.
    starts = [at(network, "e", 0.0), at(network, "b", 5.0), at(network, "b", 3.0)]
    fleet = fleet_of(space, starts, probe=10.0, gamma=0.1)
    fleet.state.entries = [None, at(network, "a", 100.0), at(network, "a", 100.0)]
    out = fleet.observe(at(network, "c", 50.0))
    assert out.dispatch.moved == "v0"
    assert out.moved_by == pytest.approx(0.1)
    assert fleet.state.positions[0] == at(network, "e", 0.1)
    assert fleet.state.positions[1] == pytest.approx(at(network, "b", 3.0), abs=1e-12)
    assert fleet.state.positions[2] == pytest.approx(at(network, "b", 1.0), abs=1e-12)
    assert fleet.state.updates == [1, 0, 0]
    assert out.backed_off == ((1, fleet.state.positions[1]), (2, fleet.state.positions[2]))


_ANYONE = Requirement(np.zeros(3, dtype=np.int64), np.ones(1, dtype=np.int64))


def _stream(network: CompiledNetwork, seed: int, n: int) -> list[NetPosition]:
    rng = np.random.default_rng(seed)
    edges = rng.integers(network.n_edges, size=n)
    return [NetPosition(int(e), float(rng.uniform(0.0, 100.0))) for e in edges]


def _config(*, probe: float | None, annealing: Annealing | None = None) -> FleetConfig:
    return FleetConfig(
        objective=ROUTING, schedule=InverseScaling(20.0, 0.75), seed=7, probe=probe,
        annealing=annealing,
    )  # fmt: skip


def _run(space: RoadSpace, config: FleetConfig, targets: list[NetPosition]) -> Fleet[NetPosition]:
    starts = [NetPosition(e, 50.0) for e in range(3)]
    fleet = Fleet.create(space, [(Vehicle(f"v{i}"), p) for i, p in enumerate(starts)], config)
    for z in targets:
        fleet.observe(z)
    return fleet


@pytest.mark.parametrize("annealing", [None, Annealing(5.0, 0.99)])
def test_same_seed_same_targets_bit_identical(
    network: CompiledNetwork, space: RoadSpace, annealing: Annealing | None
) -> None:
    targets = _stream(network, 1, 400)
    one = _run(space, _config(probe=10.0, annealing=annealing), targets)
    two = _run(space, _config(probe=10.0, annealing=annealing), targets)
    assert json.dumps(one.snapshot()) == json.dumps(two.snapshot())
    assert any(e is not None for e in one.state.entries) or annealing is not None


@pytest.mark.parametrize("annealing", [None, Annealing(5.0, 0.99)])
def test_kept_back_probes_are_those_of_the_current_references(
    network: CompiledNetwork, space: RoadSpace, annealing: Annealing | None
) -> None:
    # the fleet recomputes only the probes of vehicles that moved; a fleet that forgets
    # them before every target must take exactly the same steps
    config = _config(probe=10.0, annealing=annealing)
    kept = _run(space, config, [])
    fresh = _run(space, config, [])
    slower = RoadSpace(network, cost="time").with_travel_times({"b": 30.0, "d": 5.0})
    for k, z in enumerate(_stream(network, 3, 400)):
        if k == 200:  # new travel times: every probe window is measured anew
            kept.space = fresh.space = slower
        fresh.restore(fresh.snapshot())  # new position objects: every probe measured anew
        one, two = kept.observe(z), fresh.observe(z)
        assert (one.new_position, one.backed_off) == (two.new_position, two.backed_off)
        assert kept.state.positions == fresh.state.positions
        assert kept.state.entries == fresh.state.entries
    assert json.dumps(kept.snapshot()) == json.dumps(fresh.snapshot())


def test_snapshot_restore_round_trip_with_entries(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    targets = _stream(network, 2, 600)
    whole = _run(space, _config(probe=10.0), targets)
    half = _run(space, _config(probe=10.0), targets[:300])
    assert any(e is not None for e in half.state.entries)
    data = json.loads(json.dumps(half.snapshot()))
    resumed = _run(space, _config(probe=10.0), [])
    resumed.restore(data)
    assert resumed.state.entries == half.state.entries
    for z in targets[300:]:
        resumed.observe(z)
    assert resumed.snapshot() == whole.snapshot()


def test_snapshot_without_entries_restores_them_as_unknown(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    fleet = _run(space, _config(probe=10.0), _stream(network, 3, 50))
    data = fleet.snapshot()
    del data["entries"]
    fleet.restore(data)
    assert fleet.state.entries == [None, None, None]


def test_without_probe_the_rule_is_exactly_the_papers(
    network: CompiledNetwork, space: RoadSpace
) -> None:
    fleet = _run(space, _config(probe=None), [])
    for z in _stream(network, 4, 300):
        old = list(fleet.state.positions)
        found = space.assign(z, old, np.ones(3), _ANYONE)
        gamma = fleet.step_size(found.mover)
        out = fleet.observe(z)
        step = min(gamma, found.mover_cost)
        expected = space.advance(old[found.mover], z, found.route, step) if step > 0 else z
        assert out.moved_by == step and out.backed_off == ()
        assert fleet.state.positions == [
            expected if i == found.mover else p for i, p in enumerate(old)
        ]
    assert fleet.state.entries == [None, None, None]


def test_probe_has_no_effect_on_a_space_without_jumps() -> None:
    rng = np.random.default_rng(5)
    targets = [PlanePosition(float(x), float(y)) for x, y in rng.uniform(0, 10, size=(200, 2))]
    runs = []
    for probe in (None, 0.5):
        config = FleetConfig(objective=ROUTING, schedule=InverseScaling(1.0, 0.75), probe=probe)
        starts = [PlanePosition(1.0, 1.0), PlanePosition(9.0, 9.0)]
        fleet = Fleet.create(
            EuclideanPlane(side=10.0), [(Vehicle(f"v{i}"), p) for i, p in enumerate(starts)], config
        )
        for z in targets:
            fleet.observe(z)
        runs.append(fleet.state.positions)
    assert runs[0] == runs[1]
