"""Lagrangian lower bound and site reduction for the p-median (Beasley 1993).

Relaxing the assignment constraints ``sum_i x_ij = 1`` of the p-median with
multipliers ``lambda_j`` leaves a problem solved by inspection:

.. math::

    L(\\lambda) = \\sum_j \\lambda_j + \\min_{|S| = p} \\sum_{i \\in S} \\rho_i,
    \\qquad \\rho_i = \\sum_j \\min(0, w_j c_{ij} - \\lambda_j),

so ``S(lambda)`` is the ``p`` sites of smallest ``rho``. ``L(lambda)`` is a
lower bound on the optimum for every ``lambda`` and its maximum equals the
LP-relaxation bound; subgradient ascent (step ``pi (UB - L) / |g|^2`` along
``g_j = 1 - #{i in S(lambda): w_j c_ij < lambda_j}``) approaches it in a few
hundred ``O(n_sites * n_demand)`` passes.

The same ``rho`` also bounds every solution that *contains* a site ``i``
outside ``S(lambda)``: ``L - rho_(p) + rho_i`` (swap ``i`` for the worst of
``S``), and every solution that *omits* a site ``i`` inside ``S(lambda)``:
``L - rho_i + rho_(p+1)``. When such a bound exceeds the best known value
``UB``, no better solution opens (resp. closes) that site, so the exact solver
may drop (resp. fix open) it. Each test is valid on its own, so the tests of
all iterations are accumulated.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from routing_svc.types import BoolArray, FloatArray, IntArray

#: A bound must exceed the best value by this fraction to drop or fix a site.
SAFETY = 1e-9


@dataclass(frozen=True, slots=True)
class LagrangianResult:
    """Outcome of the subgradient ascent.

    Attributes
    ----------
    lower : float
        Best lower bound ``max L(lambda)`` found.
    upper : float
        Value of ``sites`` (never above the incumbent's).
    sites : IntArray
        Best sites known: the incumbent or a better ``S(lambda)``.
    dropped : BoolArray
        Sites that no solution better than ``upper`` can open.
    fixed_open : BoolArray
        Sites that every solution better than ``upper`` must open.
    """

    lower: float
    upper: float
    sites: IntArray
    dropped: BoolArray
    fixed_open: BoolArray


def lagrangian_bound(
    weighted: FloatArray,
    p: int,
    incumbent: IntArray,
    *,
    deadline: float,
    max_iterations: int = 600,
    gap: float = 1e-9,
) -> LagrangianResult:
    """Subgradient ascent on the Lagrangian dual of the p-median.

    Parameters
    ----------
    weighted : FloatArray
        ``w_j c_ij``, shape ``(n_sites, n_demand)``.
    p : int
        Number of sites to open, ``1 <= p <= n_sites``.
    incumbent : IntArray
        A feasible solution (``p`` distinct sites), e.g. from the heuristic.
    deadline : float
        ``time.perf_counter()`` value after which the ascent stops.
    max_iterations : int
        Iteration cap.
    gap : float
        Stop once ``upper - lower <= gap * upper``.

    Returns
    -------
    LagrangianResult
    """
    n = weighted.shape[0]
    sites = np.sort(np.asarray(incumbent, dtype=np.int64))
    upper = _value(weighted, sites)
    multipliers = weighted[sites].min(axis=0)  # lambda_j = w_j c1_j of the incumbent
    dropped = np.zeros(n, dtype=bool)
    fixed_open = np.zeros(n, dtype=bool)
    lower, factor, stall = -math.inf, 2.0, 0
    for _ in range(max_iterations):
        reduced = np.minimum(weighted - multipliers, 0.0)
        rho = reduced.sum(axis=1)
        order = np.argsort(rho, kind="stable")
        chosen = order[:p]
        value = float(multipliers.sum() + rho[chosen].sum())
        # Site tests with this lambda (see the module docstring).
        limit = upper * (1.0 + SAFETY) + SAFETY * abs(value)
        dropped |= value - rho[chosen[-1]] + rho > limit
        if p < n:
            fixed_open[chosen] |= value - rho[chosen] + rho[order[p]] > limit
        candidate = np.sort(chosen)
        if (found := _value(weighted, candidate)) < upper:
            sites, upper = candidate, found
        if value > lower:
            lower, stall = value, 0
        else:
            stall += 1
            if stall >= 20:
                factor, stall = factor / 2.0, 0
        if upper - lower <= gap * upper or factor < 1e-4 or time.perf_counter() > deadline:
            break
        covered = (reduced[chosen] < 0.0).sum(axis=0)
        direction = 1.0 - covered
        norm = float(direction @ direction)
        if norm == 0.0:
            lower = max(lower, value)  # lambda is optimal for the dual
            break
        multipliers = multipliers + factor * (upper - value) / norm * direction
    dropped[sites] = False  # the best known sites stay available
    return LagrangianResult(lower, upper, sites, dropped, fixed_open & ~dropped)


def _value(weighted: FloatArray, sites: IntArray) -> float:
    return math.fsum(weighted[sites].min(axis=0).tolist())
