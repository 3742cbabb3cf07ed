"""Reference optima in the plane for the routing objective (10).

- :func:`cooper`: Cooper's alternating location-allocation for the continuous
  multi-source Weber problem ``min sum_j w_j min_i |p_i - z_j|``: assign every
  demand point to its nearest site, move each site to the weighted geometric
  median of its points (Weiszfeld's iteration), repeat until the assignment
  stops changing. It reaches a local optimum; :func:`best_cooper` keeps the
  best of several restarts, our stand-in for the continuous optimum (the
  exact problem is NP-hard).
- :func:`discrete_pmedian`: the exact p-median over candidate sites (the
  demand points themselves), by the MILP of
  :func:`routing_svc.optimum.pmedian.solve_pmedian` (HiGHS via
  ``scipy.optimize.milp``).
"""

from __future__ import annotations

import numpy as np

from routing_svc.optimum.pmedian import solve_pmedian
from routing_svc.paper.plane_demand import distances, expected_cost
from routing_svc.types import FloatArray


def weiszfeld(
    points: FloatArray, weights: FloatArray, *, start: FloatArray, iterations: int = 30
) -> FloatArray:
    """The weighted geometric median of ``points`` (Weiszfeld's fixed-point iteration).

    ``x <- sum_j (w_j z_j / d_j) / sum_j (w_j / d_j)`` with ``d_j = |x - z_j|``
    floored at ``1e-9`` (a point that coincides with ``x`` keeps the iteration
    finite).
    """
    x = np.asarray(start, dtype=np.float64).copy()
    for _ in range(iterations):
        d = np.maximum(np.hypot(*(points - x).T), 1e-9)
        factor = weights / d
        new = factor @ points / factor.sum()
        if np.hypot(*(new - x)) < 1e-10:
            return np.asarray(new, dtype=np.float64)
        x = new
    return x


def cooper(
    points: FloatArray, weights: FloatArray, *, start: FloatArray, rounds: int = 100
) -> FloatArray:
    """Cooper's location-allocation from ``start`` (``(p, 2)``); returns the sites."""
    sites = np.asarray(start, dtype=np.float64).copy()
    previous = None
    for _ in range(rounds):
        nearest = distances(points, sites).argmin(axis=1)
        if previous is not None and np.array_equal(nearest, previous):
            break
        for i in range(len(sites)):
            members = nearest == i
            if members.any():
                sites[i] = weiszfeld(points[members], weights[members], start=sites[i])
        previous = nearest
    return sites


def best_cooper(
    points: FloatArray,
    weights: FloatArray,
    *,
    count: int,
    restarts: int,
    rng: np.random.Generator,
) -> FloatArray:
    """The best of ``restarts`` runs of :func:`cooper` from random demand points.

    Starting sites are drawn with probability proportional to the weights, as
    a fleet placed at the first targets it sees would be.
    """
    probabilities = weights / weights.sum()
    best, best_cost = None, np.inf
    for _ in range(restarts):
        chosen = rng.choice(len(points), size=count, replace=False, p=probabilities)
        sites = cooper(points, weights, start=points[chosen])
        cost = expected_cost(points, sites, power=1.0, weights=weights)
        if cost < best_cost:
            best, best_cost = sites, cost
    assert best is not None
    return best


def discrete_pmedian(
    points: FloatArray, weights: FloatArray, *, count: int
) -> tuple[FloatArray, bool]:
    """The exact p-median with the demand points as candidate sites (MILP).

    Returns the sites and whether HiGHS proved them optimal.
    """
    solution = solve_pmedian(distances(points, points), weights, count, method="milp")
    return np.asarray(points[list(solution.sites)], dtype=np.float64), solution.proven_optimal
