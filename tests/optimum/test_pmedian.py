"""p-median solvers against brute-force enumeration of every p-subset."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from routing_svc.errors import InvalidInput
from routing_svc.optimum.lagrangian import lagrangian_bound
from routing_svc.optimum.pmedian import objective, solve_pmedian
from routing_svc.sa.interchange import greedy_interchange, neighbourhood_search
from routing_svc.types import FloatArray
from tests.optimum.conftest import all_subset_values, brute_force_pmedian


def euclidean_instance(rng: np.random.Generator, n: int, m: int) -> tuple[FloatArray, FloatArray]:
    """Sites and demand points in the unit square; random weights."""
    sites, atoms = rng.random((n, 2)), rng.random((m, 2))
    costs = np.hypot(*(sites[:, None, :] - atoms[None, :, :]).transpose(2, 0, 1))
    weights = rng.random(m)
    return costs, weights / weights.sum()


def asymmetric_instance(rng: np.random.Generator, n: int, m: int) -> tuple[FloatArray, FloatArray]:
    """A random non-negative matrix: no symmetry, no triangle inequality."""
    costs = rng.exponential(10.0, size=(n, m)).round(3)
    weights = rng.random(m)
    return costs, weights / weights.sum()


def windy_instance(rng: np.random.Generator, n: int, m: int) -> tuple[FloatArray, FloatArray]:
    """Directed plane costs ``|b - a| - 0.5 (b.x - a.x)`` (east is cheaper than west)."""
    sites, atoms = rng.random((n, 2)), rng.random((m, 2))
    delta = atoms[None, :, :] - sites[:, None, :]
    costs = np.hypot(delta[..., 0], delta[..., 1]) - 0.5 * delta[..., 0]
    weights = rng.random(m)
    return costs, weights / weights.sum()


INSTANCES = {"euclidean": euclidean_instance, "asymmetric": asymmetric_instance}
STRUCTURED = {"euclidean": euclidean_instance, "windy": windy_instance}


@pytest.mark.parametrize("kind", sorted(INSTANCES))
@pytest.mark.parametrize("reduce", [True, False])
@pytest.mark.parametrize("seed", range(6))
def test_milp_equals_brute_force(kind: str, reduce: bool, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, m, p = int(rng.integers(6, 12)), int(rng.integers(8, 25)), int(rng.integers(1, 5))
    costs, weights = INSTANCES[kind](rng, n, m)
    best = brute_force_pmedian(costs, weights, p)
    solution = solve_pmedian(costs, weights, p, method="milp", reduce=reduce)
    assert solution.method == "milp"
    assert solution.proven_optimal
    assert len(set(solution.sites)) == p
    assert solution.objective == pytest.approx(best, rel=1e-9, abs=1e-12)
    assert solution.objective == objective(costs, weights, list(solution.sites))
    assert solution.lower_bound is not None
    assert solution.lower_bound <= best * (1 + 1e-9) + 1e-12


@pytest.mark.parametrize("seed", range(3))
def test_milp_grows_restrictions_to_the_optimum(seed: int) -> None:
    """Many sites for few vehicles: the first restricted models overflow."""
    rng = np.random.default_rng(100 + seed)
    costs, weights = asymmetric_instance(rng, 30, 40)
    best = brute_force_pmedian(costs, weights, 3)
    solution = solve_pmedian(costs, weights, 3, method="milp", reduce=False)
    assert solution.proven_optimal
    assert solution.objective == pytest.approx(best, rel=1e-9)


@pytest.mark.parametrize("kind", sorted(STRUCTURED))
@pytest.mark.parametrize("seed", range(3))
def test_heuristic_is_close_to_milp_and_never_better(kind: str, seed: int) -> None:
    rng = np.random.default_rng(200 + seed)
    costs, weights = STRUCTURED[kind](rng, 80, 200)
    exact = solve_pmedian(costs, weights, 6, method="milp", time_limit=30.0)
    heuristic = solve_pmedian(costs, weights, 6, method="heuristic")
    assert exact.proven_optimal
    assert heuristic.method == "heuristic" and not heuristic.proven_optimal
    assert heuristic.lower_bound is None
    assert heuristic.objective >= exact.objective * (1 - 1e-9)
    assert heuristic.objective <= exact.objective * 1.03


@pytest.mark.parametrize("kind", sorted(STRUCTURED))
def test_neighbourhood_search_leaves_the_local_optima_of_the_interchange(kind: str) -> None:
    """Where greedy + fast interchange stop above the optimum, the search reaches it."""
    stuck = 0
    for seed in range(60):
        costs, weights = STRUCTURED[kind](np.random.default_rng(400 + seed), 18, 30)
        best = brute_force_pmedian(costs, weights, 4)
        local = greedy_interchange(costs, weights, 4)
        if objective(costs, weights, local) <= best * (1 + 1e-9):
            continue
        stuck += 1
        searched = neighbourhood_search(costs, weights, local)
        assert len(set(searched.tolist())) == 4
        assert objective(costs, weights, searched) == pytest.approx(best, rel=1e-9)
        heuristic = solve_pmedian(costs, weights, 4, method="heuristic")
        assert heuristic.objective == pytest.approx(best, rel=1e-9)
    assert stuck >= 3  # the instances do exercise the search


@pytest.mark.parametrize("seed", range(3))
def test_neighbourhood_search_never_loses_and_repeats_itself(seed: int) -> None:
    costs, weights = asymmetric_instance(np.random.default_rng(500 + seed), 40, 60)
    start = greedy_interchange(costs, weights, 5)
    first = neighbourhood_search(costs, weights, start, seed=seed)
    again = neighbourhood_search(costs, weights, start, seed=seed)
    assert first.tolist() == again.tolist()
    assert objective(costs, weights, first) <= objective(costs, weights, start)
    every_site = np.arange(7, dtype=np.int64)
    assert neighbourhood_search(costs[:7], weights, every_site).tolist() == every_site.tolist()


@pytest.mark.parametrize("seed", range(4))
def test_p1_is_the_best_weighted_row(seed: int) -> None:
    rng = np.random.default_rng(300 + seed)
    costs, weights = asymmetric_instance(rng, 40, 30)
    best_row = int(np.argmin(costs @ weights))
    for method in ("milp", "heuristic"):
        solution = solve_pmedian(costs, weights, 1, method=method)
        assert solution.sites == (best_row,)
        assert solution.objective == pytest.approx(float(costs[best_row] @ weights), rel=1e-12)


def test_p_equal_to_sites_opens_everything() -> None:
    costs, weights = asymmetric_instance(np.random.default_rng(4), 5, 9)
    solution = solve_pmedian(costs, weights, 5, method="milp")
    assert solution.sites == (0, 1, 2, 3, 4)
    assert solution.proven_optimal
    assert solution.objective == pytest.approx(float(costs.min(axis=0) @ weights))


def test_auto_uses_milp_up_to_500_sites_and_the_heuristic_above() -> None:
    rng = np.random.default_rng(5)
    small = solve_pmedian(*asymmetric_instance(rng, 20, 10), 2)
    large = solve_pmedian(*asymmetric_instance(rng, 501, 10), 2)
    assert small.method == "milp" and small.proven_optimal
    assert large.method == "heuristic"


def test_zero_weight_atoms_do_not_matter() -> None:
    rng = np.random.default_rng(6)
    costs, weights = asymmetric_instance(rng, 10, 12)
    padded_costs = np.hstack([costs, rng.random((10, 5)) * 1000])
    padded_weights = np.concatenate([weights, np.zeros(5)])
    expected = brute_force_pmedian(costs, weights, 3)
    solution = solve_pmedian(padded_costs, padded_weights, 3, method="milp")
    assert solution.objective == pytest.approx(expected, rel=1e-9)


def test_same_input_gives_same_sites() -> None:
    costs, weights = euclidean_instance(np.random.default_rng(7), 120, 150)
    first = solve_pmedian(costs, weights, 7, method="heuristic")
    second = solve_pmedian(costs.copy(), weights.copy(), 7, method="heuristic")
    assert first.sites == second.sites


def test_a_tiny_time_limit_still_returns_a_valid_solution() -> None:
    costs, weights = euclidean_instance(np.random.default_rng(8), 150, 300)
    solution = solve_pmedian(costs, weights, 9, method="milp", time_limit=1e-6)
    assert len(set(solution.sites)) == 9
    assert solution.objective == objective(costs, weights, list(solution.sites))
    assert solution.lower_bound is not None and solution.lower_bound <= solution.objective


@pytest.mark.parametrize("seed", range(5))
def test_interchange_ends_in_a_swap_local_optimum(seed: int) -> None:
    rng = np.random.default_rng(400 + seed)
    costs, weights = asymmetric_instance(rng, 25, 30)
    sites = greedy_interchange(costs, weights, 4)
    value = objective(costs, weights, sites)
    for leave, enter in itertools.product(range(4), range(25)):
        if enter in sites:
            continue
        swapped = sites.copy()
        swapped[leave] = enter
        assert objective(costs, weights, swapped) >= value * (1 - 1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_lagrangian_bound_and_site_tests_hold_for_every_subset(seed: int) -> None:
    rng = np.random.default_rng(500 + seed)
    costs, weights = euclidean_instance(rng, 11, 20)
    p = 3
    values = all_subset_values(costs, weights, p)
    start = np.array(max(values, key=values.__getitem__), dtype=np.int64)  # the worst subset
    result = lagrangian_bound(costs * weights, p, start, deadline=float("inf"))
    assert result.lower <= min(values.values()) * (1 + 1e-9)
    assert result.upper == pytest.approx(objective(costs, weights, result.sites), rel=1e-12)
    for subset, value in values.items():
        if value < result.upper * (1 - 1e-9):
            assert not result.dropped[list(subset)].any()
            assert set(np.flatnonzero(result.fixed_open)) <= set(subset)


@pytest.mark.parametrize(
    ("costs", "weights", "p", "message"),
    [
        (np.ones((3,)), np.ones(3), 1, "2-D"),
        (np.ones((3, 4)), np.ones(3), 1, "weights"),
        (-np.ones((3, 4)), np.ones(4), 1, "finite"),
        (np.full((3, 4), np.nan), np.ones(4), 1, "finite"),
        (np.full((3, 4), np.inf), np.ones(4), 1, "finite"),
        (np.ones((3, 4)), -np.ones(4), 1, "weights"),
        (np.ones((3, 4)), np.zeros(4), 1, "weights"),
        (np.ones((3, 4)), np.ones(4), 0, "between 1 and"),
        (np.ones((3, 4)), np.ones(4), 4, "between 1 and"),
        (np.ones((3, 4)), np.ones(4), True, "integer"),
    ],
)
def test_bad_input_is_rejected(
    costs: FloatArray, weights: FloatArray, p: int, message: str
) -> None:
    with pytest.raises(InvalidInput, match=message):
        solve_pmedian(costs, weights, p)


def test_bad_options_are_rejected() -> None:
    costs, weights = np.ones((3, 4)), np.ones(4)
    with pytest.raises(InvalidInput, match="method"):
        solve_pmedian(costs, weights, 1, method="best")  # type: ignore[arg-type]
    with pytest.raises(InvalidInput, match="time_limit"):
        solve_pmedian(costs, weights, 1, time_limit=0.0)
