"""The discrete p-median problem: the optimum that stochastic approximation seeks.

For the routing objective (eq. (10) of Le Ny & Pappas) with identical vehicles,
the minimisers of the expected waiting time are p-medians: choose ``p`` sites
``S`` among candidates to minimise

.. math:: F(S) = \\sum_j w_j \\min_{i \\in S} c_{ij},

with ``c_ij`` the directed cost from candidate ``i`` to demand atom ``j`` (any
other service cost ``c(T)``, e.g. ``T**2`` for coverage, by passing the
transformed matrix).

Two methods:

- ``"heuristic"``: greedy addition and Whitaker's fast interchange to a local
  optimum, then a variable neighbourhood search from it
  (:mod:`routing_svc.sa.interchange`).
- ``"milp"``: exact. Greedy addition and the fast interchange give an
  incumbent; a Lagrangian bound (:mod:`routing_svc.optimum.lagrangian`) often
  proves it optimal at once, and otherwise drops the sites that cannot be in
  a better solution. What remains is solved with HiGHS
  (``scipy.optimize.milp``) in the assignment formulation::

      min  sum_ij w_j c_ij x_ij
      s.t. sum_i x_ij = 1            for every atom j
           x_ij <= y_i               for every pair (i, j)
           sum_i y_i = p,  y binary,  0 <= x <= 1

  ``x`` may stay continuous: for binary ``y`` an optimal ``x`` assigns each
  atom to its cheapest open site. To keep the model small, atom ``j`` first
  gets only its ``k_j`` cheapest sites plus an *overflow* variable priced at
  its ``(k_j + 1)``-th cheapest cost, a lower bound of what it pays when none
  of them is open; the restricted model is a relaxation, so its optimum (or
  HiGHS's dual bound) bounds the true optimum from below. When the best
  known sites reach that bound they are optimal; otherwise atoms that
  overflowed get twice as many sites. ``k_j = n - p + 1`` needs no overflow
  (at most ``n - p`` sites are closed), so the loop ends.

``method="auto"`` is exact when there are at most 500 candidate sites.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp
from scipy.optimize import Bounds, LinearConstraint, milp

from routing_svc.errors import InvalidInput
from routing_svc.optimum.lagrangian import lagrangian_bound
from routing_svc.sa.interchange import greedy_interchange, neighbourhood_search
from routing_svc.types import BoolArray, FloatArray, IntArray

Method = Literal["auto", "milp", "heuristic"]

#: ``method="auto"`` solves exactly up to this many candidate sites.
MILP_MAX_SITES = 500

#: Relative gap under which the best sites count as proven optimal.
PROVEN_GAP = 1e-9


@dataclass(frozen=True, slots=True)
class PMedianSolution:
    """A set of ``p`` open sites and its objective.

    Attributes
    ----------
    sites : tuple of int
        Indices (rows of the cost matrix) of the open sites, ascending.
    objective : float
        ``sum_j w_j min_{i in sites} c_ij``, recomputed exactly from the matrix.
    method : str
        ``"milp"`` if the exact method ran (see ``proven_optimal``), else
        ``"heuristic"``.
    proven_optimal : bool
        True when the objective is proven optimal within a relative ``1e-9``.
    seconds : float
        Wall-clock time of the solve (heuristic included).
    lower_bound : float or None
        Exact method: the best proven lower bound on the optimum (equal to
        ``objective`` up to ``1e-9`` relative when ``proven_optimal``), so
        ``objective / lower_bound - 1`` bounds the optimality gap even when
        time ran out. ``None`` for the heuristic.
    """

    sites: tuple[int, ...]
    objective: float
    method: str
    proven_optimal: bool
    seconds: float
    lower_bound: float | None = None


def solve_pmedian(
    costs: FloatArray,
    weights: FloatArray,
    p: int,
    *,
    method: Method = "auto",
    time_limit: float = 60.0,
    reduce: bool = True,
) -> PMedianSolution:
    """Choose ``p`` of the candidate sites minimising the weighted cost.

    Parameters
    ----------
    costs : FloatArray
        ``c_ij >= 0``, finite, shape ``(n_sites, n_demand)``: cost from site
        ``i`` to demand atom ``j``.
    weights : FloatArray
        ``w_j >= 0``, shape ``(n_demand,)``, positive sum.
    p : int
        Number of sites to open, ``1 <= p <= n_sites``.
    method : {"auto", "milp", "heuristic"}
        ``"auto"``: exact if ``n_sites <= 500``, else the heuristic.
    time_limit : float
        Seconds allowed to the exact method after the heuristic. When it runs
        out, the best sites found are returned with ``proven_optimal=False``.
    reduce : bool
        Exact method only: bound with the Lagrangian relaxation and drop the
        sites it excludes before the MILP (default). ``False`` goes straight
        to the MILP (for comparison and testing).

    Returns
    -------
    PMedianSolution

    Raises
    ------
    InvalidInput
        Bad shapes, negative/non-finite costs or weights, ``p`` out of range,
        an unknown method or a non-positive time limit.
    """
    started = time.perf_counter()
    c, w = _validated(costs, weights, p)
    if method not in ("auto", "milp", "heuristic"):
        raise InvalidInput(f"method must be 'auto', 'milp' or 'heuristic', got {method!r}")
    if not math.isfinite(time_limit) or time_limit <= 0:
        raise InvalidInput(f"time_limit must be a finite number > 0, got {time_limit!r}")
    exact = method == "milp" or (method == "auto" and c.shape[0] <= MILP_MAX_SITES)
    sites = greedy_interchange(c, w, int(p))
    lower: float | None = None
    if exact:
        deadline = time.perf_counter() + time_limit
        sites, lower = _solve_exact(c, w, int(p), incumbent=sites, deadline=deadline, reduce=reduce)
    else:
        sites = neighbourhood_search(c, w, sites)
    value = objective(costs, weights, sites)
    proven = lower is not None and value - lower <= PROVEN_GAP * value
    return PMedianSolution(
        sites=tuple(sorted(int(i) for i in sites)),
        objective=value,
        method="milp" if exact else "heuristic",
        proven_optimal=proven,
        seconds=time.perf_counter() - started,
        lower_bound=None if lower is None or not math.isfinite(lower) else min(lower, value),
    )


def objective(costs: FloatArray, weights: FloatArray, sites: IntArray | list[int]) -> float:
    """``F(S) = sum_j w_j min_{i in S} c_ij``, summed with ``math.fsum``."""
    best = np.asarray(costs, dtype=np.float64)[np.asarray(sites, dtype=np.int64)].min(axis=0)
    return math.fsum((np.asarray(weights, dtype=np.float64) * best).tolist())


def checked_costs(costs: FloatArray, weights: FloatArray) -> tuple[FloatArray, FloatArray]:
    """A site-by-atom cost matrix and the atoms' weights as float arrays, checked.

    Raises
    ------
    InvalidInput
        An empty or mis-shaped matrix, a negative or non-finite cost (an atom no site
        reaches), or weights that are negative, non-finite or sum to zero.
    """
    c = np.asarray(costs, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    if c.ndim != 2 or c.shape[0] == 0 or c.shape[1] == 0:
        raise InvalidInput(f"costs must be a non-empty 2-D matrix, got shape {c.shape}")
    if w.shape != (c.shape[1],):
        raise InvalidInput(f"weights of shape {w.shape} do not match {c.shape[1]} demand atoms")
    if not np.all(np.isfinite(c)) or np.any(c < 0):
        raise InvalidInput("costs must be finite and >= 0 (is every atom reachable?)")
    if not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise InvalidInput("weights must be finite, >= 0, with a positive sum")
    return c, w


def _validated(costs: FloatArray, weights: FloatArray, p: int) -> tuple[FloatArray, FloatArray]:
    """Check the inputs; return the matrix and weights of the atoms with ``w_j > 0``."""
    c, w = checked_costs(costs, weights)
    if isinstance(p, bool) or not isinstance(p, int | np.integer):
        raise InvalidInput(f"p must be an integer, got {p!r}")
    if not 1 <= p <= c.shape[0]:
        raise InvalidInput(f"p must be between 1 and the number of sites ({c.shape[0]}), got {p}")
    keep = w > 0
    if keep.all():  # the matrix itself (the solvers only read it), not a copy
        return np.ascontiguousarray(c), w
    return np.ascontiguousarray(c[:, keep]), w[keep]


def _solve_exact(
    c: FloatArray,
    w: FloatArray,
    p: int,
    *,
    incumbent: IntArray,
    deadline: float,
    reduce: bool,
) -> tuple[IntArray, float]:
    """Lagrangian bound and reduction, then the MILP; return (sites, lower bound)."""
    n = c.shape[0]
    if p == n:
        sites = np.arange(n, dtype=np.int64)
        return sites, objective(c, w, sites)
    if not reduce:
        none = np.zeros(n, dtype=bool)
        return _solve_milp(c, w, p, incumbent=incumbent, fixed=none, deadline=deadline)
    bound = lagrangian_bound(c * w, p, incumbent, deadline=deadline)
    best, upper = bound.sites, bound.upper
    keep = np.flatnonzero(~bound.dropped)
    fixed = bound.fixed_open[keep]
    if upper - bound.lower <= PROVEN_GAP * upper or keep.size <= p or fixed.sum() > p:
        return best, upper  # no solution better than ``best`` exists
    local = np.searchsorted(keep, best)
    found, lower = _solve_milp(c[keep], w, p, incumbent=local, fixed=fixed, deadline=deadline)
    return keep[found], max(lower, bound.lower)


def _solve_milp(
    c: FloatArray,
    w: FloatArray,
    p: int,
    *,
    incumbent: IntArray,
    fixed: BoolArray,
    deadline: float,
) -> tuple[IntArray, float]:
    """Growing restrictions of the assignment MILP (module docstring).

    Every solution better than ``incumbent`` opens the ``fixed`` sites, so
    ``min(F(incumbent), optimum of the model)`` is the true optimum. Returns
    the best sites found and a lower bound on the optimum.
    """
    n, m = c.shape
    full = n - p + 1
    rank = np.argsort(c, axis=0, kind="stable")  # rank[r, j]: r-th cheapest site of atom j
    position = np.empty_like(rank)
    position[rank, np.arange(m)] = np.arange(n)[:, None]
    best, upper = incumbent, objective(c, w, incumbent)
    used = position[incumbent].min(axis=0) + 1  # rank of the incumbent's site, plus one
    k = np.minimum(full, np.maximum(2 * used, max(8, -(-2 * n // p))))
    scale = float((c * w).max()) or 1.0
    lower = -math.inf
    while (remaining := deadline - time.perf_counter()) > 0:
        sites, round_lower, overflow = _restricted_milp(
            c, w / scale, p, rank, k, fixed=fixed, time_limit=remaining
        )
        if sites is not None and (value := objective(c, w, sites)) < upper:
            best, upper = sites, value
        lower = max(lower, min(upper, round_lower * scale))
        grow = overflow & (k < full)
        if upper - lower <= PROVEN_GAP * upper or sites is None or not grow.any():
            break  # proven, or out of time (or numerical trouble)
        k[grow] = np.minimum(full, 2 * k[grow])
    return best, lower


def _restricted_milp(
    c: FloatArray,
    w: FloatArray,
    p: int,
    rank: IntArray,
    k: IntArray,
    *,
    fixed: BoolArray,
    time_limit: float,
) -> tuple[IntArray | None, float, BoolArray]:
    """Solve one restriction; return (sites or None, lower bound, overflowing atoms)."""
    n, m = c.shape
    starts = np.concatenate([[0], np.cumsum(k)])
    n_pairs = int(starts[-1])
    pair_atom = np.repeat(np.arange(m, dtype=np.int64), k)
    pair_site = rank[np.arange(n_pairs) - starts[pair_atom], pair_atom]
    spill = np.flatnonzero(k < n - p + 1)  # atoms with an overflow variable
    # Variables: y (n), x (n_pairs), overflow u (spill.size).
    n_var = n + n_pairs + spill.size
    cost = np.concatenate(
        [
            np.zeros(n),
            c[pair_site, pair_atom] * w[pair_atom],
            c[rank[k[spill], spill], spill] * w[spill],
        ]
    )
    pair_col = n + np.arange(n_pairs)
    spill_col = n + n_pairs + np.arange(spill.size)
    assign_rows = np.concatenate([pair_atom, spill])
    assign_cols = np.concatenate([pair_col, spill_col])
    assign = sp.csr_array((np.ones(assign_rows.size), (assign_rows, assign_cols)), (m, n_var))
    link = sp.csr_array(
        (
            np.concatenate([np.ones(n_pairs), -np.ones(n_pairs)]),
            (np.tile(np.arange(n_pairs), 2), np.concatenate([pair_col, pair_site])),
        ),
        shape=(n_pairs, n_var),
    )
    count = sp.csr_array((np.ones(n), (np.zeros(n, dtype=np.int64), np.arange(n))), (1, n_var))
    lower_bounds = np.zeros(n_var)
    lower_bounds[:n][fixed] = 1.0
    result = milp(
        cost,
        constraints=[
            LinearConstraint(assign, 1.0, 1.0),
            LinearConstraint(link, -np.inf, 0.0),
            LinearConstraint(count, float(p), float(p)),
        ],
        integrality=np.concatenate([np.ones(n), np.zeros(n_pairs + spill.size)]),
        bounds=Bounds(lower_bounds, 1.0),
        options={"time_limit": float(time_limit), "mip_rel_gap": PROVEN_GAP / 10, "disp": False},
    )
    bound = result.get("mip_dual_bound")
    lower = float(bound) if bound is not None and math.isfinite(bound) else -math.inf
    if result.status == 0 and result.fun is not None:
        lower = max(lower, float(result.fun) * (1.0 - PROVEN_GAP / 10))
    overflow = np.zeros(m, dtype=bool)
    if result.x is None:
        return None, lower, overflow
    overflow[spill] = result.x[n + n_pairs :] > 1e-9
    sites = np.argsort(-result.x[:n], kind="stable")[:p].astype(np.int64)
    return sites, lower, overflow
