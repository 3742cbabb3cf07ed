"""The p-median heuristic: greedy addition, Whitaker's fast interchange, neighbourhood search.

Greedy addition opens, ``p`` times, the site that lowers
``F(S) = sum_j w_j min_{i in S} c_ij`` most; lazily (Minoux 1978): a site's
last decrease bounds its next one, so only sites whose bound could win are
priced again. The fast interchange of Whitaker (1983), as in Hansen &
Mladenovic (1997), then prices every swap (open ``i``, close ``r``) in one
``O(n_sites * n_demand)`` pass using the cheapest (``c1_j``, at site
``a1_j``) and second cheapest (``c2_j``) open site of every atom:

- ``gain_i = sum_j w_j min(c_ij - c1_j, 0)``: atoms that move to ``i``;
- ``loss_ir = sum_{j: a1_j = r} w_j max(min(c_ij, c2_j) - c1_j, 0)``: atoms of
  ``r`` that fall back to ``i`` or to their second site;

and applies the best swap ``gain_i + loss_ir`` while it is negative. The
result is a local optimum of the Teitz-Bart (1968) swap neighbourhood. Since
``loss_ir >= 0``, a site whose gain (or a lower bound of it, carried from the
last pass) cannot beat the best swap so far is not priced further. Both run as
numba kernels (:mod:`routing_svc.sa.interchange_kernels`).

A local optimum of the swap neighbourhood can still be a little above the
optimum (0.85 % on one of the DRT benchmark instances). The variable
neighbourhood search of Hansen & Mladenovic (1997) then *shakes* the best
sites by ``k`` random swaps, runs the fast interchange from there and keeps
the result if it is better (``k`` back to 1), else tries ``k + 1`` (up to
3, then 1 again), and stops after a number of shakes in a row without a
gain. The shakes are drawn from a fixed seed, so a solve is deterministic.
"""

from __future__ import annotations

import math

import numpy as np

from routing_svc.sa.interchange_kernels import (
    best_swap,
    fill_gains,
    lazy_greedy,
    nearest_two,
    relax_bounds,
    swap_losses,
)
from routing_svc.types import FloatArray, IntArray

#: A swap must lower the objective by more than this fraction to be applied.
SWAP_TOLERANCE = 1e-12

#: The variable neighbourhood search stops after this many shakes in a row without a gain.
SHAKES_WITHOUT_GAIN = 20

#: The largest shake: this many random swaps of open sites for closed ones.
LARGEST_SHAKE = 3


def greedy_interchange(c: FloatArray, w: FloatArray, p: int) -> IntArray:
    """Greedy addition followed by the fast interchange to a local optimum.

    Parameters
    ----------
    c : FloatArray
        Costs ``c_ij >= 0``, shape ``(n_sites, n_demand)``.
    w : FloatArray
        Weights ``w_j >= 0``.
    p : int
        Number of sites, ``1 <= p <= n_sites``.

    Returns
    -------
    IntArray
        ``p`` distinct site indices (unordered).
    """
    return fast_interchange(c, w, greedy(c, w, p))


def neighbourhood_search(
    c: FloatArray,
    w: FloatArray,
    sites: IntArray,
    *,
    shakes_without_gain: int = SHAKES_WITHOUT_GAIN,
    seed: int = 0,
) -> IntArray:
    """Variable neighbourhood search from a local optimum ``sites``.

    Parameters
    ----------
    c : FloatArray
        Costs ``c_ij >= 0``, shape ``(n_sites, n_demand)``.
    w : FloatArray
        Weights ``w_j >= 0``.
    sites : IntArray
        Distinct open sites, usually a local optimum of :func:`fast_interchange`.
    shakes_without_gain : int
        Stop after this many shakes in a row that found nothing better.
    seed : int
        Seed of the random shakes.

    Returns
    -------
    IntArray
        Sites whose ``F`` is at most that of ``sites``.
    """
    best = np.array(sites, dtype=np.int64)
    largest = min(LARGEST_SHAKE, best.size, c.shape[0] - best.size)
    if largest == 0:
        return best
    rng = np.random.default_rng(seed)
    c, w = _contiguous(c, w)
    transposed = np.ascontiguousarray(c.T)
    value = _value(c, w, best)
    size, misses = 1, 0
    while misses < shakes_without_gain:
        candidate = best.copy()
        candidate[rng.choice(best.size, size=size, replace=False)] = rng.choice(
            np.setdiff1d(np.arange(c.shape[0]), best), size=size, replace=False
        )
        candidate = fast_interchange(c, w, candidate, transposed=transposed)
        candidate_value = _value(c, w, candidate)
        if candidate_value < value * (1 - SWAP_TOLERANCE):
            best, value, size, misses = candidate, candidate_value, 1, 0
        else:
            size, misses = size % largest + 1, misses + 1
    return best


def greedy(c: FloatArray, w: FloatArray, p: int) -> IntArray:
    """Open sites one at a time, each time the one that lowers ``F`` most.

    Lazy (Minoux's accelerated greedy, :func:`routing_svc.sa.interchange_kernels.lazy_greedy`):
    only the sites whose bound could beat the best are priced again. Among sites of
    equal ``F`` after opening, the lowest index opens. Sums run over the atoms in
    ascending order, so where totals are equal in exact arithmetic but not once
    rounded, that order's rounding decides.

    Returns
    -------
    IntArray
        The ``p`` sites in ascending order.
    """
    c, w = _contiguous(c, w)
    if not 0 <= p <= c.shape[0]:
        raise ValueError(f"greedy addition opens 0 to {c.shape[0]} sites, not {p}")
    return np.sort(lazy_greedy(c, w, int(p)))


def fast_interchange(
    c: FloatArray, w: FloatArray, sites: IntArray, *, transposed: FloatArray | None = None
) -> IntArray:
    """Apply best-improvement swaps from ``sites`` until none lowers ``F``.

    Each pass (:func:`routing_svc.sa.interchange_kernels.best_swap`) finds the swap of
    least ``gain_i + loss_ir`` (the first in the order of closed sites, then of
    positions in ``sites``); it is applied if it lowers ``F`` by more than
    :data:`SWAP_TOLERANCE` of ``F`` and the exactly summed ``F`` of the result is lower.
    The entering site takes the leaving one's position. The losses of a site are summed
    when it is first priced and then kept, each pass summing again only the positions
    whose atoms changed (:func:`routing_svc.sa.interchange_kernels.swap_losses`), over
    ``c`` transposed: ``transposed`` if given (``c.T``, C-contiguous, shared by several
    calls on the same costs), else made at the first swap.
    """
    c, w = _contiguous(c, w)
    n, m = c.shape
    open_sites = np.array(sites, dtype=np.int64)
    p = open_sites.size
    if p == 0:
        raise ValueError("the fast interchange needs an open site")
    is_open = np.zeros(n, dtype=bool)
    is_open[open_sites] = True
    c1, c2, a1 = np.empty(m), np.empty(m), np.empty(m, dtype=np.int64)
    n1, n2, b1 = np.empty(m), np.empty(m), np.empty(m, dtype=np.int64)
    nearest_two(c, open_sites, c1, c2, a1)
    bounds = np.full(n, np.inf)  # of the gains, see best_swap; the first pass needs them all
    fill_gains(c, w, c1, np.flatnonzero(~is_open), bounds)
    exact = ~is_open
    ct = transposed
    losses = np.empty((n, p))
    kept = np.zeros(n, dtype=bool)
    current = math.fsum((w * c1).tolist())
    while True:
        limit = -SWAP_TOLERANCE * current
        enter, leave, delta = best_swap(
            c, w, is_open, c1, c2, a1, losses, kept, bounds, exact, limit
        )
        if enter < 0 or not delta < limit:
            return open_sites
        candidate = open_sites.copy()
        candidate[leave] = enter
        nearest_two(c, candidate, n1, n2, b1)
        value = math.fsum((w * n1).tolist())
        if not value < current:
            return open_sites
        if ct is None:
            ct = np.ascontiguousarray(c.T)
        relax_bounds(ct, w, bounds, exact, c1, n1)
        closing = open_sites[leave]
        is_open[closing], is_open[enter] = False, True
        bounds[closing], bounds[enter] = -np.inf, np.inf
        exact[closing] = exact[enter] = kept[closing] = kept[enter] = False
        swap_losses(ct, w, c1, c2, a1, n1, n2, b1, losses, kept)
        open_sites, current = candidate, value
        c1, c2, a1, n1, n2, b1 = n1, n2, b1, c1, c2, a1


def _contiguous(c: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    return np.ascontiguousarray(c, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64)


def _value(c: FloatArray, w: FloatArray, sites: IntArray) -> float:
    return math.fsum((w * c[sites].min(axis=0)).tolist())
