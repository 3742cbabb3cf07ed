"""The heterogeneous optimum: exact cost against hand and loop references, MILP and
heuristic against brute force over every site assignment, and the p-median case."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
import pytest

from routing_svc.demand import DemandDistribution
from routing_svc.errors import InvalidInput, UnmetRequirement
from routing_svc.network import CompiledNetwork, RoadSpace
from routing_svc.optimum import candidate_sites, expected_cost, solve_pmedian
from routing_svc.optimum.heterogeneous import (
    HeterogeneousSolution,
    Method,
    RequirementClass,
    heterogeneous_cost,
    heterogeneous_cost_from_times,
    heterogeneous_optimum,
    solve_heterogeneous,
)
from routing_svc.types import FloatArray, NetPosition, PlanePosition
from tests.optimum.conftest import PlaneCosts

Mix = list[RequirementClass]

MIXES: list[Mix] = [
    [RequirementClass(("A",), 0.5), RequirementClass(("A", "B"), 0.5)],
    [RequirementClass(("A", "A"), 2.0), RequirementClass((), 1.0)],
    [
        RequirementClass(("A", "A"), 0.3),
        RequirementClass(("A", "B"), 0.5),
        RequirementClass(("B",), 0.2),
    ],
]


def loop_cost(
    times: FloatArray, types: Sequence[str], weights: FloatArray, mix: Mix, power: float
) -> float:
    """``J`` target by target: sort each required type's times, take the k-th, the last arrival."""
    total_share = sum(c.share for c in mix)
    total = 0.0
    for cls in mix:
        for j in range(times.shape[1]):
            if not cls.requires:
                done = min(times[i, j] for i in range(len(types)))
            else:
                done = 0.0
                for name in set(cls.requires):
                    k = cls.requires.count(name)
                    mine = sorted(times[i, j] for i in range(len(types)) if types[i] == name)
                    done = max(done, mine[k - 1])
            total += cls.share / total_share * weights[j] * done**power
    return total


def brute_force(
    costs: FloatArray,
    weights: FloatArray,
    types: Sequence[str],
    speeds: Sequence[float],
    mix: Mix,
    power: float,
) -> float:
    """Smallest ``J`` over every assignment of a site to every vehicle."""
    v = np.asarray(speeds, dtype=np.float64)[:, None]
    return min(
        loop_cost(costs[list(at)] / v, types, weights, mix, power)
        for at in itertools.product(range(costs.shape[0]), repeat=len(types))
    )


def relocations_and_swaps(solution: HeterogeneousSolution, n_sites: int) -> list[list[int]]:
    """Every assignment one relocation or one swap away from ``solution``."""
    at = list(solution.sites)
    out: list[list[int]] = []
    for i in range(len(at)):
        out.extend([*at[:i], s, *at[i + 1 :]] for s in range(n_sites))
        for k in range(i + 1, len(at)):
            swapped = at.copy()
            swapped[i], swapped[k] = at[k], at[i]
            out.append(swapped)
    return out


# -- exact cost ----------------------------------------------------------------------------


def test_exact_cost_by_hand() -> None:
    times = np.array([[1.0, 4.0], [3.0, 2.0], [2.0, 5.0]])
    types = ["A", "A", "B"]
    w = np.array([0.25, 0.75])
    # class A: (1, 2); class AB: (max(1, 2), max(2, 5)) = (2, 5)
    mix = [RequirementClass(("A",), 0.5), RequirementClass(("A", "B"), 0.5)]
    assert heterogeneous_cost_from_times(times, types, w, mix) == pytest.approx(
        0.5 * (0.25 * 1 + 0.75 * 2) + 0.5 * (0.25 * 2 + 0.75 * 5)
    )
    # shares are relative: (1, 1) is (0.5, 0.5)
    same = [RequirementClass(("A",), 1.0), RequirementClass(("A", "B"), 1.0)]
    assert heterogeneous_cost_from_times(times, types, w, same) == pytest.approx(3.0)
    # two A's: the second A arrives at (3, 4); squared costs
    two = [RequirementClass(("A", "A"), 1.0)]
    assert heterogeneous_cost_from_times(times, types, w, two, power=2.0) == pytest.approx(
        0.25 * 9 + 0.75 * 16
    )
    # any one vehicle (the default): (1, 2)
    assert heterogeneous_cost_from_times(times, types, w) == pytest.approx(0.25 + 1.5)


@pytest.mark.parametrize("seed", range(12))
def test_exact_cost_matches_a_per_target_loop(seed: int) -> None:
    rng = np.random.default_rng(seed)
    types = ["A", "B", "A", "B", "A"][: int(rng.integers(3, 6))]
    times = rng.uniform(0.0, 10.0, (len(types), int(rng.integers(1, 9))))
    w = rng.uniform(0.0, 1.0, (times.shape[1],))
    mix = MIXES[seed % len(MIXES)]
    power = [1.0, 2.0, 1.5][seed % 3]
    assert heterogeneous_cost_from_times(times, types, w, mix, power=power) == pytest.approx(
        loop_cost(times, types, w, mix, power), rel=1e-12
    )


def test_exact_cost_of_any_one_vehicle_is_the_homogeneous_expected_cost() -> None:
    rng = np.random.default_rng(3)
    positions = [PlanePosition(*p) for p in rng.uniform(0, 10, (4, 2))]
    demand = DemandDistribution.from_masses(
        "test", tuple(PlanePosition(*p) for p in rng.uniform(0, 10, (9, 2))), rng.uniform(1, 2, 9)
    )
    speeds = [1.0, 2.0, 0.5, 1.25]
    types = ["A", "B", "A", "C"]
    for power in (1.0, 2.0):
        assert heterogeneous_cost(
            PlaneCosts(), positions, types, speeds, demand, power=power
        ) == pytest.approx(expected_cost(PlaneCosts(), positions, speeds, demand, power=power))


# -- solvers against brute force -------------------------------------------------------------


@pytest.mark.parametrize("seed", range(10))
def test_milp_and_heuristic_against_brute_force_on_random_matrices(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    n_sites, n_atoms = int(rng.integers(3, 6)), int(rng.integers(2, 5))
    costs = rng.uniform(0.0, 10.0, (n_sites, n_atoms))
    w = rng.uniform(0.1, 1.0, n_atoms)
    types = ["A", "B", "A"] if seed % 2 else ["A", "A", "B", "B"]
    speeds = [1.0, 2.0, 1.0] if seed % 2 else [1.0, 1.5, 1.0, 1.0]
    mix = MIXES[seed % len(MIXES)]
    power = 2.0 if seed % 3 == 0 else 1.0
    best = brute_force(costs, w, types, speeds, mix, power)

    exact = solve_heterogeneous(costs, w, types, speeds, mix, power=power, method="milp")
    assert exact.method == "milp" and exact.proven_optimal
    assert exact.objective == pytest.approx(best, rel=1e-9)
    assert exact.lower_bound is not None and exact.lower_bound == pytest.approx(best, rel=1e-7)
    at = np.asarray(exact.sites)
    recomputed = loop_cost(costs[at] / np.asarray(speeds)[:, None], types, w, mix, power)
    assert recomputed == pytest.approx(exact.objective, rel=1e-12)

    heuristic = solve_heterogeneous(costs, w, types, speeds, mix, power=power, method="heuristic")
    assert heuristic.method == "heuristic" and not heuristic.proven_optimal
    assert heuristic.objective >= best * (1 - 1e-12)
    v = np.asarray(speeds)[:, None]
    for moved in relocations_and_swaps(heuristic, n_sites):  # a local optimum
        value = loop_cost(costs[moved] / v, types, w, mix, power)
        assert value >= heuristic.objective * (1 - 1e-9)
    again = solve_heterogeneous(costs, w, types, speeds, mix, power=power, method="heuristic")
    assert again.sites == heuristic.sites and again.objective == heuristic.objective


@pytest.mark.parametrize("power", [1.0, 1.5, 2.0])
def test_heuristic_ends_at_a_local_optimum_of_a_larger_instance(power: float) -> None:
    # too many assignments for brute force (40 ** 6): every relocation and swap of the
    # heuristic's answer, priced target by target, costs at least as much
    rng = np.random.default_rng(int(power * 10))
    costs = rng.uniform(0.0, 10.0, (40, 25))
    w = rng.uniform(0.0, 1.0, 25)
    types, speeds = ["A", "A", "B", "A", "B", "B"], [1.0, 1.5, 1.0, 1.0, 2.0, 1.0]
    mix = MIXES[2]
    heuristic = solve_heterogeneous(costs, w, types, speeds, mix, power=power, method="heuristic")
    v = np.asarray(speeds)[:, None]
    at = np.asarray(heuristic.sites)
    assert loop_cost(costs[at] / v, types, w, mix, power) == pytest.approx(
        heuristic.objective, rel=1e-12
    )
    for moved in relocations_and_swaps(heuristic, 40):
        assert loop_cost(costs[moved] / v, types, w, mix, power) >= heuristic.objective * (1 - 1e-9)


def test_two_required_vehicles_of_one_type_may_share_a_site() -> None:
    # all demand at atom 0 needs two A's; site 0 is next to it, the others far
    costs = np.array([[0.0, 9.0], [5.0, 0.0], [6.0, 1.0]])
    w = np.array([1.0, 0.0])
    mix = [RequirementClass(("A", "A"), 1.0)]
    methods: tuple[Method, ...] = ("milp", "heuristic")
    for method in methods:
        solution = solve_heterogeneous(costs, w, ["A", "A", "B"], [1, 1, 1], mix, method=method)
        assert solution.sites[:2] == (0, 0) and solution.objective == 0.0


def test_milp_and_heuristic_on_the_drt_network(drt_network: CompiledNetwork) -> None:
    net = drt_network
    space = RoadSpace(net, cost="length")
    rng = np.random.default_rng(7)
    edges = rng.choice(net.n_edges, size=4, replace=False)
    demand = DemandDistribution.from_masses(
        "test",
        tuple(NetPosition(int(e), float(net.length[e]) / 2) for e in edges),
        np.array([1.0, 2.0, 1.0, 3.0]),
    )
    sites = candidate_sites(net, demand, max_sites=9)
    costs = space.cost_matrix(sites, list(demand.positions))
    types, speeds = ["A", "A", "B"], [1.0, 1.5, 1.0]
    mix = [
        RequirementClass(("A",), 0.4),
        RequirementClass(("A", "B"), 0.3),
        RequirementClass(("A", "A"), 0.3),
    ]
    w = np.asarray(demand.weights)
    best = brute_force(costs, w, types, speeds, mix, 1.0)
    exact = solve_heterogeneous(costs, w, types, speeds, mix, method="auto")
    assert exact.method == "milp" and exact.proven_optimal
    assert exact.objective == pytest.approx(best, rel=1e-9)
    heuristic = solve_heterogeneous(costs, w, types, speeds, mix, method="heuristic")
    assert heuristic.objective >= best * (1 - 1e-12)
    # the network pipeline: positions whose exact cost is the objective
    positions, solution = heterogeneous_optimum(space, sites, demand, types, speeds, mix)
    assert solution.objective == pytest.approx(best, rel=1e-9)
    assert heterogeneous_cost(space, positions, types, speeds, demand, mix) == pytest.approx(
        solution.objective, rel=1e-12
    )


# -- the homogeneous case is the p-median -------------------------------------------------------


@pytest.mark.parametrize("power", [1.0, 2.0])
def test_one_type_unit_speeds_any_one_vehicle_is_the_pmedian(power: float) -> None:
    rng = np.random.default_rng(11)
    costs = rng.uniform(0.0, 10.0, (12, 15))
    w = rng.uniform(0.0, 1.0, 15)
    pmedian = solve_pmedian(costs**power, w, 3)
    same = solve_heterogeneous(costs, w, ["A"] * 3, [1.0] * 3, power=power)
    assert same.objective == pytest.approx(pmedian.objective, rel=1e-12)
    assert sorted(same.sites) == list(pmedian.sites) and same.proven_optimal
    # types do not matter when any one vehicle serves
    typed = solve_heterogeneous(costs, w, ["A", "B", "C"], [1.0] * 3, power=power)
    assert typed.objective == pytest.approx(pmedian.objective, rel=1e-12)
    # nor does naming the only type: the MILP reaches the same optimum
    named = solve_heterogeneous(
        costs, w, ["A"] * 3, [1.0] * 3, [RequirementClass(("A",), 1.0)], power=power, method="milp"
    )
    assert named.proven_optimal
    assert named.objective == pytest.approx(pmedian.objective, rel=1e-9)


# -- bad input ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("mix", "error"),
    [
        ([RequirementClass(("C",), 1.0)], UnmetRequirement),
        ([RequirementClass(("B", "B"), 1.0)], UnmetRequirement),
        ([RequirementClass(("A",), 0.0)], InvalidInput),
        ([RequirementClass(("A",), -1.0)], InvalidInput),
        ([RequirementClass(("A",), math.nan)], InvalidInput),
        ([RequirementClass(("A",), math.inf)], InvalidInput),
        ([RequirementClass(("",), 1.0)], InvalidInput),
        ([], InvalidInput),
    ],
)
def test_bad_mixes_raise(mix: Mix, error: type[Exception]) -> None:
    costs, w = np.ones((3, 2)), np.ones(2)
    with pytest.raises(error):
        solve_heterogeneous(costs, w, ["A", "A", "B"], [1.0] * 3, mix)
    with pytest.raises(error):
        heterogeneous_cost_from_times(np.ones((3, 2)), ["A", "A", "B"], w, mix)


@pytest.mark.parametrize(
    "change",
    [
        {"costs": -np.ones((3, 2))},
        {"costs": np.full((3, 2), np.nan)},
        {"costs": np.ones(3)},
        {"weights": np.ones(3)},
        {"weights": np.zeros(2)},
        {"speeds": [1.0, 1.0]},
        {"speeds": [1.0, 0.0, 1.0]},
        {"speeds": [1.0, np.inf, 1.0]},
        {"types": []},
        {"power": 0.0},
        {"method": "simplex"},
        {"time_limit": 0.0},
    ],
)
def test_bad_input_raises(change: dict[str, object]) -> None:
    args: dict[str, object] = {
        "costs": np.ones((3, 2)),
        "weights": np.ones(2),
        "types": ["A", "A", "B"],
        "speeds": [1.0, 1.0, 1.0],
        "power": 1.0,
        "method": "auto",
        "time_limit": 10.0,
    }
    args.update(change)
    with pytest.raises(InvalidInput):
        solve_heterogeneous(
            args["costs"],  # type: ignore[arg-type]
            args["weights"],  # type: ignore[arg-type]
            args["types"],  # type: ignore[arg-type]
            args["speeds"],  # type: ignore[arg-type]
            power=args["power"],  # type: ignore[arg-type]
            method=args["method"],  # type: ignore[arg-type]
            time_limit=args["time_limit"],  # type: ignore[arg-type]
        )


def test_bad_times_raise() -> None:
    w = np.ones(2)
    with pytest.raises(InvalidInput):
        heterogeneous_cost_from_times(np.ones((2, 2)), ["A", "A", "B"], w)
    with pytest.raises(InvalidInput):
        heterogeneous_cost_from_times(-np.ones((3, 2)), ["A", "A", "B"], w)
    with pytest.raises(InvalidInput):
        heterogeneous_cost_from_times(np.ones((3, 2)), ["A", "A", "B"], w, power=-1.0)
