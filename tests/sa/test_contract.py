"""The contract every space must keep, checked on the plane and on a real road network."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from routing_svc.network import RoadSpace, load_network
from routing_svc.network.catalogue import resolve_network
from routing_svc.sa import (
    ROUTING,
    Annealing,
    EuclideanPlane,
    Fleet,
    FleetConfig,
    InverseScaling,
    Vehicle,
)
from routing_svc.sa.requirements import build_requirement
from routing_svc.types import NetPosition, PlanePosition

DRT = load_network(resolve_network("drt"))


def plane_case(rng: np.random.Generator, n: int) -> tuple[Any, list[Any]]:
    space = EuclideanPlane(side=10.0)
    return space, [PlanePosition(float(x), float(y)) for x, y in rng.uniform(0, 10, (n, 2))]


def road_case(rng: np.random.Generator, n: int) -> tuple[Any, list[Any]]:
    space = RoadSpace(DRT, cost="length")
    edges = rng.integers(DRT.n_edges, size=n)
    return space, [NetPosition(int(e), float(rng.uniform(0, DRT.length[e]))) for e in edges]


CASES = {"plane": plane_case, "road": road_case}


@pytest.fixture(params=sorted(CASES))
def case(request: pytest.FixtureRequest) -> Any:
    return CASES[request.param]


def test_assign_is_pure_and_repeatable(case: Any) -> None:
    rng = np.random.default_rng(0)
    space, positions = case(rng, 12)
    _, targets = case(rng, 30)
    before = list(positions)
    speeds = np.ones(len(positions))
    req, _ = build_requirement(["default"] * len(positions), None)
    for z in targets:
        a = space.assign(z, positions, speeds, req)
        b = space.assign(z, positions, speeds, req)
        assert (a.served_by, a.times, a.mover) == (b.served_by, b.times, b.mover)
    assert positions == before


def test_advance_moves_exactly_the_requested_cost(case: Any) -> None:
    rng = np.random.default_rng(1)
    space, positions = case(rng, 1)
    _, targets = case(rng, 40)
    speeds = np.ones(1)
    req, _ = build_requirement(["default"], None)
    for z in targets:
        found = space.assign(z, positions, speeds, req)
        amount = 0.37 * found.mover_cost
        moved = space.advance(positions[0], z, found.route, amount)
        left = space.cost_matrix([moved], [z])[0, 0]
        assert left == pytest.approx(found.mover_cost - amount, rel=1e-9, abs=1e-6)
        assert space.advance(positions[0], z, found.route, found.mover_cost + 1.0) == z


def run_fleet(space: Any, starts: list[Any], targets: list[Any], seed: int) -> Fleet[Any]:
    fleet = Fleet.create(
        space,
        [(Vehicle(f"v{i}"), p) for i, p in enumerate(starts)],
        FleetConfig(
            objective=ROUTING,
            schedule=InverseScaling(0.2 * space.typical_cost(), 0.75),
            annealing=Annealing(0.05 * space.typical_cost(), 1.0),
            seed=seed,
        ),
    )
    for z in targets:
        fleet.observe(z)
    return fleet


def test_same_seed_same_positions_and_replay_equals_live(case: Any) -> None:
    rng = np.random.default_rng(2)
    space, starts = case(rng, 6)
    _, targets = case(rng, 300)
    a = run_fleet(space, starts, targets, 5)
    b = run_fleet(space, starts, targets, 5)
    assert json.dumps(a.snapshot()) == json.dumps(b.snapshot())
    # a fleet restored from a snapshot halfway continues exactly like the live one
    half = run_fleet(space, starts, targets[:150], 5)
    data = json.loads(json.dumps(half.snapshot()))
    resumed = run_fleet(space, starts, [], 5)
    resumed.restore(data)
    for z in targets[150:]:
        resumed.observe(z)
    assert json.dumps(resumed.snapshot()) == json.dumps(a.snapshot())
    c = run_fleet(space, starts, targets, 6)
    assert json.dumps(c.snapshot()) != json.dumps(a.snapshot())


def test_one_vehicle_converges_to_the_exact_1_median_of_a_network() -> None:
    net = load_network(resolve_network("grid"))
    space = RoadSpace(net, cost="length")
    rng = np.random.default_rng(4)
    # demand spread along every street (atoms every ~10 m), heavier around a hotspot
    atoms: list[NetPosition] = []
    mass: list[float] = []
    for e in range(net.n_edges):
        length = float(net.length[e])
        pieces = max(1, int(length // 10))
        for i in range(pieces):
            p = NetPosition(e, (i + 0.5) * length / pieces)
            x, y = space.xy(p)
            atoms.append(p)
            mass.append(length / pieces * np.exp(-((x - 300) ** 2 + (y - 700) ** 2) / 2 / 250**2))
    weights = np.array(mass) / sum(mass)
    # exact 1-median by enumeration: every atom and every junction (Hakimi)
    sites = atoms + [NetPosition(e, 0.0) for e in range(net.n_edges)]
    best = float((space.cost_matrix(sites, atoms) @ weights).min())
    fleet = Fleet.create(
        space,
        [(Vehicle("v"), NetPosition(0, 0.0))],
        FleetConfig(objective=ROUTING, schedule=InverseScaling(0.5 * space.typical_cost(), 0.75)),
    )
    for j in rng.choice(len(atoms), size=20000, p=weights):
        fleet.observe(atoms[j])
    final = float(space.cost_matrix(fleet.state.positions, atoms)[0] @ weights)
    assert final <= best * 1.01
    start = float(space.cost_matrix([NetPosition(0, 0.0)], atoms)[0] @ weights)
    assert start > best * 1.2  # the start was far from the median
