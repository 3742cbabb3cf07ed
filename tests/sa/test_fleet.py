"""Fleet behaviour on the plane: assignment, heterogeneous rule, determinism."""

from __future__ import annotations

import json

import numpy as np
import pytest

from routing_svc.errors import UnmetRequirement
from routing_svc.sa import (
    COVERAGE,
    ROUTING,
    Annealing,
    Constant,
    Counting,
    EuclideanPlane,
    Fleet,
    FleetConfig,
    InverseScaling,
    Vehicle,
)
from routing_svc.types import PlanePosition as Pt


def make_fleet(
    vehicles: list[tuple[Vehicle, Pt]], *, config: FleetConfig | None = None
) -> Fleet[Pt]:
    cfg = config or FleetConfig(objective=ROUTING, schedule=Constant(1.0))
    return Fleet.create(EuclideanPlane(side=10.0), vehicles, cfg)


def test_closest_vehicle_serves_and_only_it_moves() -> None:
    fleet = make_fleet([(Vehicle("b"), Pt(10.0, 0.0)), (Vehicle("a"), Pt(0.0, 0.0))])
    out = fleet.observe(Pt(3.0, 4.0))
    assert out.dispatch.served_by == ("a",)
    assert out.dispatch.moved == "a"
    assert out.dispatch.cost == 5.0
    assert fleet.positions["a"] == pytest.approx(Pt(0.6, 0.8), abs=1e-15)
    assert fleet.positions["b"] == Pt(10.0, 0.0)
    assert fleet.state.updates == [1, 0]


def test_assign_is_pure() -> None:
    fleet = make_fleet([(Vehicle("a"), Pt(0.0, 0.0)), (Vehicle("b"), Pt(9.0, 9.0))])
    before = json.dumps(fleet.snapshot())
    d = fleet.assign(Pt(8.0, 8.0))
    assert d.moved == "b"
    assert json.dumps(fleet.snapshot()) == before


def test_ties_break_by_vehicle_id() -> None:
    fleet = make_fleet([(Vehicle("z"), Pt(-1.0, 0.0)), (Vehicle("m"), Pt(1.0, 0.0))])
    assert fleet.assign(Pt(0.0, 0.0)).moved == "m"


def test_ab_target_moves_the_vehicle_that_arrives_last() -> None:
    fleet = make_fleet(
        [
            (Vehicle("a1", "A"), Pt(0.0, 0.0)),
            (Vehicle("a2", "A"), Pt(8.0, 0.0)),
            (Vehicle("b1", "B", speed=2.0), Pt(0.0, 6.0)),
            (Vehicle("b2", "B"), Pt(-9.0, -9.0)),
        ]
    )
    # A: a1 at distance 1, B: b1 at distance 5 with speed 2 -> time 2.5, arrives last
    d = fleet.assign(Pt(1.0, 0.0), ["A", "B"])
    assert d.served_by == ("a1", "b1")
    assert d.times[0] == 1.0
    assert d.times[1] == pytest.approx(np.hypot(1.0, 6.0) / 2.0) and len(d.times) == 2
    assert d.moved == "b1"
    out = fleet.observe(Pt(1.0, 0.0), ["B", "A"])
    assert out.dispatch.moved == "b1"
    assert out.moved_by == 0.5  # routing: gamma / v
    assert fleet.positions["a1"] == Pt(0.0, 0.0)


def test_multiset_requirement_needs_two_of_a_type() -> None:
    fleet = make_fleet(
        [
            (Vehicle("a1", "A"), Pt(0.0, 0.0)),
            (Vehicle("a2", "A"), Pt(5.0, 0.0)),
            (Vehicle("a3", "A"), Pt(9.0, 0.0)),
        ]
    )
    d = fleet.assign(Pt(1.0, 0.0), ["A", "A"])
    assert d.served_by == ("a1", "a2") and d.moved == "a2" and d.cost == 4.0
    with pytest.raises(UnmetRequirement):
        fleet.assign(Pt(1.0, 0.0), ["A", "B"])
    with pytest.raises(UnmetRequirement):
        fleet.assign(Pt(1.0, 0.0), ["A"] * 4)


def test_per_vehicle_and_fleet_counting() -> None:
    vehicles = [(Vehicle("a"), Pt(0.0, 0.0)), (Vehicle("b"), Pt(100.0, 0.0))]
    per_vehicle = make_fleet(
        vehicles, config=FleetConfig(objective=ROUTING, schedule=InverseScaling(1.0, 1.0))
    )
    per_fleet = make_fleet(
        vehicles,
        config=FleetConfig(
            objective=ROUTING, schedule=InverseScaling(1.0, 1.0), counting=Counting.FLEET
        ),
    )
    for fleet in (per_vehicle, per_fleet):
        fleet.observe(Pt(0.0, 10.0))
        fleet.observe(Pt(0.0, 10.0))
    # b has never moved: per vehicle its next step is gamma_0, per fleet gamma_2
    assert per_vehicle.step_size(1) == 1.0
    assert per_fleet.step_size(1) == pytest.approx(1.0 / 3.0)
    assert per_vehicle.positions["a"] == Pt(0.0, 1.5)


def stream(seed: int, n: int) -> list[Pt]:
    rng = np.random.default_rng(seed)
    return [Pt(float(x), float(y)) for x, y in rng.uniform(0.0, 10.0, size=(n, 2))]


@pytest.mark.parametrize("annealing", [None, Annealing(0.5, 0.8)])
def test_same_seed_same_targets_bit_identical(annealing: Annealing | None) -> None:
    def run() -> str:
        fleet = make_fleet(
            [(Vehicle(f"v{i}"), Pt(float(i), float(i))) for i in range(5)],
            config=FleetConfig(
                objective=ROUTING,
                schedule=InverseScaling(2.0, 0.75),
                annealing=annealing,
                seed=7,
            ),
        )
        for z in stream(3, 500):
            fleet.observe(z)
        return json.dumps(fleet.snapshot())

    assert run() == run()


def test_annealing_changes_the_path_but_decays() -> None:
    def final(annealing: Annealing | None) -> dict[str, Pt]:
        fleet = make_fleet(
            [(Vehicle("v"), Pt(0.0, 0.0))],
            config=FleetConfig(
                objective=ROUTING, schedule=InverseScaling(2.0, 0.75), annealing=annealing
            ),
        )
        for z in stream(1, 300):
            fleet.observe(z)
        return fleet.positions

    plain, noisy = final(None), final(Annealing(1.0, 1.0))
    assert plain != noisy
    assert np.hypot(plain["v"].x - noisy["v"].x, plain["v"].y - noisy["v"].y) < 1.0


def test_snapshot_restore_round_trip_exact() -> None:
    fleet = make_fleet([(Vehicle("a"), Pt(0.1, 0.2)), (Vehicle("b"), Pt(9.0, 9.0))])
    for z in stream(5, 50):
        fleet.observe(z)
    data = json.loads(json.dumps(fleet.snapshot()))
    clone = make_fleet([(Vehicle("a"), Pt(0.0, 0.0)), (Vehicle("b"), Pt(0.0, 0.0))])
    clone.restore(data)
    assert clone.positions == fleet.positions
    assert clone.state.updates == fleet.state.updates


def test_one_vehicle_routing_converges_to_the_geometric_median() -> None:
    # demand: three atoms with weights; the weighted 1-median of (0,0),(4,0),(0,3)
    # with weights (0.5, 0.25, 0.25) is the heavy point (0,0) (its weight >= 1/2).
    rng = np.random.default_rng(11)
    atoms = [Pt(0.0, 0.0), Pt(4.0, 0.0), Pt(0.0, 3.0)]
    fleet = make_fleet(
        [(Vehicle("v"), Pt(3.0, 3.0))],
        config=FleetConfig(objective=ROUTING, schedule=InverseScaling(1.0, 0.75)),
    )
    for j in rng.choice(3, size=20000, p=[0.5, 0.25, 0.25]):
        fleet.observe(atoms[j])
    p = fleet.positions["v"]
    assert np.hypot(p.x, p.y) < 0.05


def test_one_vehicle_coverage_converges_to_the_mean() -> None:
    fleet = make_fleet(
        [(Vehicle("v"), Pt(3.0, 3.0))],
        config=FleetConfig(objective=COVERAGE, schedule=InverseScaling(1.0, 1.0)),
    )
    targets = stream(2, 2000)
    for z in targets:
        fleet.observe(z)
    mean = np.mean(np.asarray(targets), axis=0)
    # gamma_k = 1/(k+1): the position is exactly the running mean (MacQueen)
    assert fleet.positions["v"].x == pytest.approx(mean[0], abs=1e-9)
    assert fleet.positions["v"].y == pytest.approx(mean[1], abs=1e-9)
