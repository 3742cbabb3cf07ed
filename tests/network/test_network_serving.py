"""The compiled single-target update gives bit for bit what the space's methods give.

:meth:`Fleet.observe` on a :class:`RoadSpace` serves a target that needs any
one vehicle through :meth:`RoadSpace.serving` (one numba call). The reference
here is the same fleet on a space without it, which goes through
:meth:`RoadSpace.assign`, the probe's methods and :meth:`RoadSpace.advance`,
one at a time. Every outcome and the whole state must be equal after every
target, over random targets (on edge ends, on references, anywhere), with
the other kinds of updates in between (a target with a requirement, new
travel times, a restored snapshot) that the compiled columns must notice.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from routing_svc.errors import Unreachable
from routing_svc.network import RoadSpace
from routing_svc.network.costs import CostKind
from routing_svc.sa import Fleet, FleetConfig, Vehicle, learning_config
from routing_svc.sa.consolidation import ConsolidationPolicy
from routing_svc.sa.fleet import Outcome
from routing_svc.sa.objectives import Objective
from routing_svc.sa.schedules import Constant, Counting, InverseScaling
from routing_svc.types import NetPosition
from tests.network.conftest import NetCase


class MethodsOnly(RoadSpace):
    """A road space without the compiled update: the fleet uses the methods one by one."""

    serving = None  # type: ignore[assignment]


def _methods_only(space: RoadSpace) -> MethodsOnly:
    twin = MethodsOnly.__new__(MethodsOnly)
    twin.__dict__.update(space.__dict__)
    return twin


@dataclasses.dataclass(frozen=True)
class Setup:
    either_way: bool
    cost: CostKind
    power: float
    counting: Counting
    probe: float | None
    """Probe window as a fraction of the space's typical cost (``None``: the paper's rule)."""
    speeds: bool = False

    def __str__(self) -> str:
        return (
            f"{'twins' if self.either_way else 'directed'}-{self.cost}-q{self.power}-"
            f"{self.counting.value}-probe{self.probe}{'-speeds' if self.speeds else ''}"
        )


SETUPS = [
    Setup(True, "length", 1.0, Counting.VEHICLE, 0.05),
    Setup(True, "time", 1.0, Counting.VEHICLE, 0.05, speeds=True),
    Setup(False, "length", 1.0, Counting.VEHICLE, 0.05),
    Setup(True, "length", 2.0, Counting.FLEET, 0.05),
    Setup(False, "time", 1.5, Counting.VEHICLE, 0.3, speeds=True),
    Setup(True, "length", 1.0, Counting.VEHICLE, 0.3),
    Setup(True, "length", 1.0, Counting.VEHICLE, None),
    Setup(False, "length", 2.0, Counting.VEHICLE, None, speeds=True),
]


def _targets(case: NetCase, rng: np.random.Generator, fleet: Fleet[NetPosition]) -> NetPosition:
    """A random target: anywhere, at an end of an edge, on a vehicle's reference, or just
    behind one on its edge (where its back probe may reach it first)."""
    kind = rng.integers(7)
    if kind == 0:
        return fleet.state.positions[int(rng.integers(len(fleet.vehicles)))]
    if kind == 6:
        edge, offset = fleet.state.positions[int(rng.integers(len(fleet.vehicles)))]
        return NetPosition(edge, float(offset * rng.uniform(0.97, 1.0)))
    (target,) = case.random_positions(rng, 1)
    if kind == 1:
        return NetPosition(target.edge, 0.0)
    if kind == 2:
        return NetPosition(target.edge, float(case.network.length[target.edge]))
    return target


def _fleets(
    case: NetCase, setup: Setup, n: int, seed: int
) -> tuple[Fleet[NetPosition], Fleet[NetPosition]]:
    rng = np.random.default_rng(seed)
    space = RoadSpace(case.network, cost=setup.cost, either_way=setup.either_way)
    typical = space.typical_cost()
    window = None if setup.probe is None else setup.probe * typical / np.sqrt(n)
    config = FleetConfig(
        objective=Objective(setup.power),
        schedule=(
            InverseScaling(0.3 * typical, 0.7) if setup.power == 1.0 else InverseScaling(0.5, 0.6)
        ),
        counting=setup.counting,
        probe=window,
        prior_counts=tuple(int(c) for c in rng.integers(0, 4, size=n)),
    )
    speeds = rng.uniform(0.5, 2.0, size=n) if setup.speeds else np.ones(n)
    vehicles = [
        (Vehicle(f"v{i:02d}", speed=float(speeds[i])), p)
        for i, p in enumerate(case.random_positions(rng, n))
    ]
    return (
        Fleet.create(space, vehicles, config),
        Fleet.create(_methods_only(space), vehicles, config),
    )


def _served_alike(
    fleet: Fleet[NetPosition], reference: Fleet[NetPosition], target: NetPosition
) -> Outcome[NetPosition] | None:
    """Serve ``target`` in both fleets, assert the same outcome and state, return the
    outcome; ``None`` when the reference finds it unreachable, which the fleet must find
    too, changing nothing."""
    try:
        expected = reference.observe(target)
    except Unreachable:
        with pytest.raises(Unreachable):
            fleet.observe(target)
        _assert_same_state(fleet, reference)
        return None
    got = fleet.observe(target)
    _assert_same(got, expected)
    _assert_same_state(fleet, reference)
    return got


def _assert_same(got: Outcome[NetPosition], expected: Outcome[NetPosition]) -> None:
    assert got == expected  # dataclass equality: every float bit for bit (no NaN here)
    assert type(got.new_position.offset) is float and type(got.new_position.edge) is int


def _assert_same_state(fleet: Fleet[NetPosition], reference: Fleet[NetPosition]) -> None:
    assert fleet.state == reference.state
    assert fleet.snapshot() == reference.snapshot()


@pytest.mark.parametrize("setup", SETUPS, ids=str)
def test_compiled_update_equals_the_methods(case: NetCase, setup: Setup) -> None:
    fleet, reference = _fleets(case, setup, n=12, seed=7)
    assert fleet.compiled_update and not reference.compiled_update
    rng = np.random.default_rng(8)
    counts: dict[str, int] = {"backed": 0, "moved_edge": 0, "entries": 0, "other": 0}
    for k in range(1500):
        target = _targets(case, rng, reference)
        got = _served_alike(fleet, reference, target)
        if got is None:
            continue
        counts["backed"] += len(got.backed_off)
        counts["moved_edge"] += got.new_position.edge != got.old_position.edge
        counts["entries"] += sum(e is not None for e in fleet.state.entries) > 0
        if k % 97 == 0:  # other updates the compiled columns must pick up
            counts["other"] += 1
            _other_update(fleet, reference, case, rng, setup)
    assert counts["moved_edge"] > 20 and counts["other"] > 10
    if setup.probe is not None:
        assert counts["backed"] > 10 and counts["entries"] > 100


def _other_update(
    fleet: Fleet[NetPosition],
    reference: Fleet[NetPosition],
    case: NetCase,
    rng: np.random.Generator,
    setup: Setup,
    kinds: int = 4,
) -> None:
    """One update of another kind: a target with a requirement, a restored snapshot, new
    travel times or a reference set from outside, or (``kinds`` 4) another probe window."""
    kind = rng.integers(kinds)
    if kind == 3:  # a new config: another probe window (or none)
        window = fleet.config.probe
        changed = dataclasses.replace(fleet.config, probe=None if window else 10.0)
        fleet.config = changed
        reference.config = changed
    elif kind == 0:  # a target with a requirement goes the methods' way in both
        target = _targets(case, rng, reference)
        try:
            expected = reference.observe(target, ["default"])
        except Unreachable:
            return
        _assert_same(fleet.observe(target, ["default"]), expected)
    elif kind == 1:  # a snapshot restored (new state lists)
        data: dict[str, Any] = reference.snapshot()
        fleet.restore(data)
        reference.restore(data)
    elif setup.cost == "time":  # new travel times: a new space
        edges = rng.choice(case.network.n_edges, size=20, replace=False)
        times = {case.network.edge_ids[e]: float(rng.uniform(1.0, 60.0)) for e in edges.tolist()}
        fleet.space = fleet.space.with_travel_times(times)  # type: ignore[attr-defined]
        reference.space = _methods_only(fleet.space)  # type: ignore[arg-type]
    else:  # a vehicle's reference set from outside
        i = int(rng.integers(len(fleet.vehicles)))
        (moved,) = case.random_positions(rng, 1)
        fleet.state.positions[i] = moved
        reference.state.positions[i] = moved
    _assert_same_state(fleet, reference)


def test_constant_steps_and_a_hand_set_entry(drt_case: NetCase) -> None:
    """Constant steps (every vehicle's gamma the same) and entries written by hand."""
    setup = Setup(True, "length", 1.0, Counting.VEHICLE, 0.3)
    fleet, reference = _fleets(drt_case, setup, n=6, seed=3)
    for f in (fleet, reference):
        f.config = dataclasses.replace(f.config, schedule=Constant(40.0))
    rng = np.random.default_rng(4)
    for _ in range(300):
        (entry,) = drt_case.random_positions(rng, 1)
        i = int(rng.integers(6))
        end = NetPosition(entry.edge, float(drt_case.network.length[entry.edge]))
        fleet.state.entries[i] = end
        reference.state.entries[i] = end
        target = _targets(drt_case, rng, reference)
        try:
            expected = reference.observe(target)
        except Unreachable:
            continue
        _assert_same(fleet.observe(target), expected)
        _assert_same_state(fleet, reference)


@pytest.mark.parametrize("either_way", [True, False], ids=["twins", "directed"])
def test_held_steps_search_through_the_kept_columns(case: NetCase, either_way: bool) -> None:
    """The ``consolidating`` rule's search (:meth:`FleetUpdate.search`, the fleet's kept
    columns) finds what :meth:`RoadSpace.assign` finds, whatever moved the references:
    held steps, consolidations, a target with a requirement, a restored snapshot, a
    reference set from outside."""
    n = 10
    setup = Setup(either_way, "length", 1.0, Counting.VEHICLE, None)
    space = RoadSpace(case.network, either_way=either_way)
    config = learning_config(
        "consolidating",
        typical_cost=space.typical_cost(),
        n_vehicles=n,
        objective=Objective(1.0),
        step_scale=0.5,
        consolidation=ConsolidationPolicy(unfitted_confidence=0.0, checked_moves=False),
    )  # held steps that move whenever their pressure asks
    rng = np.random.default_rng(11)
    vehicles = [(Vehicle(f"v{i:02d}"), p) for i, p in enumerate(case.random_positions(rng, n))]
    fleet = Fleet.create(space, vehicles, config)
    reference = Fleet.create(_methods_only(space), vehicles, config)
    counts = {"moved": 0, "consolidated": 0, "other": 0}
    for k in range(1200):
        target = _targets(case, rng, reference)
        got = _served_alike(fleet, reference, target)
        if got is None:
            continue
        assert fleet.assign(target) == reference.assign(target)
        counts["moved"] += got.moved_by > 0.0
        counts["consolidated"] += got.consolidation is not None
        if k % 89 == 0:  # no other probe window: the rule takes none
            counts["other"] += 1
            _other_update(fleet, reference, case, rng, setup, kinds=3)
    assert counts["moved"] > 20 and counts["consolidated"] >= 3 and counts["other"] > 10, counts
