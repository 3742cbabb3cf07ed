"""Compiled kernels of the p-median heuristic: lazy greedy addition and one interchange pass.

Both work on a C-contiguous cost matrix ``c`` of shape ``(n_sites, n_demand)``
and weights ``w >= 0``, and read ``c`` one row at a time. Ties go to the
lowest site index (then the lowest position), as ``np.argmin`` over the
plain numpy forms of these rules would break them.

Lazy greedy addition (Minoux 1978)
----------------------------------
Opening site ``i`` next to the open set ``S`` lowers
``F(S) = sum_j w_j min_{k in S} c_kj`` by
``d_i(S) = sum_j w_j max(b_j - c_ij, 0)`` with ``b_j = min_{k in S} c_kj``.
As ``S`` grows every ``b_j`` can only fall, so ``d_i`` can only shrink
(``F`` is supermodular). Each site therefore keeps its last computed
decrease as an upper bound in a max-heap; a round recomputes the site on top
until the top holds a decrease computed in this round, which is then at least
every other site's bound, hence its decrease. Summed in the same order over
``j``, the rounded decreases shrink too, so the bounds hold in floating point.
The heap orders equal bounds by the lower index, so the site opened is the
lowest index among the largest decreases, i.e. among the smallest
``F(S + i)``. The first round has no open site: it opens the site of least
``F({i}) = sum_j w_j c_ij`` (again the lowest index among equals).

Interchange pass (Whitaker 1983)
--------------------------------
With ``c1_j`` (at position ``a1_j`` of the open sites) and ``c2_j`` the
cheapest and second cheapest open cost of atom ``j``, a pass prices the swaps
(open the closed site ``i``, close the site at position ``r``) as
``gain_i + loss_ir`` (see :mod:`routing_svc.sa.interchange`): the gains and
the ``p`` losses of four sites at a time in one loop over ``j``, with a
length-``p`` accumulator each. Every sum runs over ``j`` in ascending order,
so every ``loss_ir`` is the sum scipy's sparse product formed.

Since ``loss_ir >= 0``, a site whose gain is above the best change found so
far (or not below the acceptance limit) cannot win; a lower bound of every
gain is carried from pass to pass (:func:`relax_bounds`), the sites are
visited from the lowest bound up and the pass stops at the first bound that
cannot win. The swap returned is the same as with every site priced.

A site's losses, once summed, are kept from pass to pass: ``loss_ir`` sums
over the atoms of position ``r`` only, so a swap changes the columns of the
positions whose atoms' ``c1``, ``c2`` or ``a1`` changed, and only those are
summed again (:func:`swap_losses`, over the transposed costs), with the same
terms in the same order as a full sum.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from routing_svc.types import BoolArray, FloatArray, IntArray

__all__ = [
    "best_swap",
    "fill_gains",
    "fill_losses",
    "gain_of",
    "lazy_greedy",
    "nearest_two",
    "relax_bounds",
    "swap_losses",
]


@njit(cache=True, nogil=True)
def lazy_greedy(c: FloatArray, w: FloatArray, p: int) -> IntArray:
    """The ``p`` sites of greedy addition, in the order they open."""
    n, m = c.shape
    picked = np.empty(p, dtype=np.int64)
    if p == 0:
        return picked
    totals = np.empty(n)
    full = n - n % 4
    for i in range(0, full, 4):  # four sums at a time, each over j in ascending order
        t0 = t1 = t2 = t3 = 0.0
        for j in range(m):
            weight = w[j]
            t0 += weight * c[i, j]
            t1 += weight * c[i + 1, j]
            t2 += weight * c[i + 2, j]
            t3 += weight * c[i + 3, j]
        totals[i], totals[i + 1], totals[i + 2], totals[i + 3] = t0, t1, t2, t3
    for i in range(full, n):
        total = 0.0
        for j in range(m):
            total += w[j] * c[i, j]
        totals[i] = total
    first, lowest = 0, np.inf
    for i in range(n):
        if totals[i] < lowest:
            first, lowest = i, totals[i]
    picked[0] = first
    nearest = c[first].copy()
    # the other sites in a max-heap of (bound, -index); every bound +inf, so
    # ascending index order is already a heap
    bounds = np.full(n - 1, np.inf)
    nodes = np.empty(n - 1, dtype=np.int64)
    k = 0
    for i in range(n):
        if i != first:
            nodes[k] = i
            k += 1
    fresh = np.full(n, -1, dtype=np.int64)
    size = n - 1
    for round_ in range(1, p):
        while True:
            top = nodes[0]
            if fresh[top] == round_:
                break
            decrease = 0.0
            for j in range(m):
                if c[top, j] < nearest[j]:
                    decrease += w[j] * (nearest[j] - c[top, j])
            fresh[top] = round_
            _sift_down(bounds, nodes, size, 0, decrease, top)
        picked[round_] = top
        size -= 1
        _sift_down(bounds, nodes, size, 0, bounds[size], nodes[size])
        for j in range(m):
            if c[top, j] < nearest[j]:
                nearest[j] = c[top, j]
    return picked


@njit(cache=True, nogil=True, inline="always")
def _sift_down(
    bounds: FloatArray, nodes: IntArray, size: int, at: int, bound: float, node: int
) -> None:
    """Place ``(bound, node)`` at ``at`` of the max-heap of ``size`` entries and sift it down.

    An entry comes before another if its bound is larger, or equal with a lower node.
    """
    i = at
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        right = child + 1
        if right < size and (
            bounds[right] > bounds[child]
            or (bounds[right] == bounds[child] and nodes[right] < nodes[child])
        ):
            child = right
        if bounds[child] < bound or (bounds[child] == bound and nodes[child] > node):
            break
        bounds[i] = bounds[child]
        nodes[i] = nodes[child]
        i = child
    if i < size:
        bounds[i] = bound
        nodes[i] = node


@njit(cache=True, nogil=True)
def nearest_two(
    c: FloatArray, sites: IntArray, c1: FloatArray, c2: FloatArray, a1: IntArray
) -> None:
    """Fill ``c1``, ``c2`` (``+inf`` for one site) and ``a1`` for the open ``sites``.

    ``a1_j`` is the first position in ``sites`` of the cheapest cost (a stable sort's
    first), and ``c2_j`` equals ``c1_j`` when two open sites tie for it.
    """
    m = c.shape[1]
    c1[:] = c[sites[0]]
    c2[:] = np.inf
    a1[:] = 0
    for r in range(1, sites.size):
        row = sites[r]
        for j in range(m):
            value = c[row, j]
            if value < c1[j]:
                c2[j] = c1[j]
                c1[j] = value
                a1[j] = r
            elif value < c2[j]:
                c2[j] = value


@njit(cache=True, nogil=True)
def best_swap(
    c: FloatArray,
    w: FloatArray,
    is_open: BoolArray,
    c1: FloatArray,
    c2: FloatArray,
    a1: IntArray,
    losses: FloatArray,
    kept: BoolArray,
    bounds: FloatArray,
    exact: BoolArray,
    limit: float,
) -> tuple[int, int, float]:
    """The swap ``(enter, leave)`` of least ``gain_enter + loss_enter,leave``, if below ``limit``.

    Among equal changes the lowest closed site, then the lowest position wins (the first
    minimum of ``np.argmin`` over the row-major ``(n_sites, p)`` matrix of changes).
    ``c1``, ``c2``, ``a1`` are those of the ``p`` open sites (:func:`nearest_two`);
    ``losses[i]`` holds ``loss_ir`` where ``kept[i]`` (kept up to date by
    :func:`swap_losses`), and a row is summed (and kept) when first needed.

    ``bounds`` holds a lower bound of every closed site's gain (``-inf``: none; ``+inf``
    at open sites), the gain itself where ``exact``. As ``loss_ir >= 0``,
    ``gain_i <= gain_i + loss_ir``: sites are visited from the lowest bound up and
    the visit stops at a bound above the best change so far or at least ``limit``. A
    visited site's gain is computed (and stored, exact) and its losses read only if its
    gain could still win. The result is the first minimum of the full matrix whenever
    that minimum is below ``limit``; else possibly ``(-1, -1, inf)``.
    """
    rows = np.empty(4, dtype=np.int64)
    pending = 0
    enter, leave, best = -1, -1, np.inf
    for i in np.argsort(bounds, kind="mergesort"):
        if is_open[i] or bounds[i] > best or bounds[i] >= limit:
            break
        if not exact[i]:
            bounds[i] = gain_of(c, w, c1, i)
            exact[i] = True
        if bounds[i] > best or bounds[i] >= limit:
            continue
        if kept[i]:
            enter, leave, best = _best_of(i, bounds[i], losses, enter, leave, best)
            continue
        rows[pending] = i
        pending += 1
        if pending == 4:
            fill_losses(c, w, c1, c2, a1, rows, losses)
            for k in range(4):
                kept[rows[k]] = True
                enter, leave, best = _best_of(rows[k], bounds[rows[k]], losses, enter, leave, best)
            pending = 0
    fill_losses(c, w, c1, c2, a1, rows[:pending], losses)
    for k in range(pending):
        kept[rows[k]] = True
        enter, leave, best = _best_of(rows[k], bounds[rows[k]], losses, enter, leave, best)
    return enter, leave, best


@njit(cache=True, nogil=True, inline="always")
def _best_of(
    i: int, gain: float, losses: FloatArray, enter: int, leave: int, best: float
) -> tuple[int, int, float]:
    """The first least ``gain_i + loss_ir`` of the swaps so far and of site ``i``'s."""
    for r in range(losses.shape[1]):
        delta = gain + losses[i, r]
        if delta < best or (delta == best and (i < enter or (i == enter and r < leave))):
            enter, leave, best = i, r, delta
    return enter, leave, best


@njit(cache=True, nogil=True)
def fill_losses(
    c: FloatArray,
    w: FloatArray,
    c1: FloatArray,
    c2: FloatArray,
    a1: IntArray,
    rows: IntArray,
    losses: FloatArray,
) -> None:
    """``losses[i, r] = loss_ir`` of the sites ``rows``, each summed over ``j`` in
    ascending order; four sites in one loop over ``j`` (four independent sums). A term
    that is not positive adds ``+0.0``, which leaves every sum as it was."""
    m = c.shape[1]
    for i in rows:
        losses[i] = 0.0
    full = rows.size - rows.size % 4
    for k in range(0, full, 4):
        i0, i1, i2, i3 = rows[k], rows[k + 1], rows[k + 2], rows[k + 3]
        for j in range(m):
            nearest, second, owner, weight = c1[j], c2[j], a1[j], w[j]
            f0 = min(c[i0, j], second) - nearest
            f1 = min(c[i1, j], second) - nearest
            f2 = min(c[i2, j], second) - nearest
            f3 = min(c[i3, j], second) - nearest
            losses[i0, owner] += weight * f0 if f0 > 0.0 else 0.0
            losses[i1, owner] += weight * f1 if f1 > 0.0 else 0.0
            losses[i2, owner] += weight * f2 if f2 > 0.0 else 0.0
            losses[i3, owner] += weight * f3 if f3 > 0.0 else 0.0
    for k in range(full, rows.size):
        i = rows[k]
        for j in range(m):
            fallback = min(c[i, j], c2[j]) - c1[j]
            losses[i, a1[j]] += w[j] * fallback if fallback > 0.0 else 0.0


@njit(cache=True, nogil=True)
def swap_losses(
    ct: FloatArray,
    w: FloatArray,
    c1: FloatArray,
    c2: FloatArray,
    a1: IntArray,
    n1: FloatArray,
    n2: FloatArray,
    b1: IntArray,
    losses: FloatArray,
    kept: BoolArray,
) -> None:
    """Bring the rows ``kept`` of ``losses`` from the open sites of ``c1, c2, a1`` to those
    of ``n1, n2, b1``; ``ct`` is the cost matrix transposed (C-contiguous). The sites of
    the swap must be out of ``kept`` (an open site has no row; a closing one is summed
    anew when needed).

    ``loss_ir`` sums over the atoms of position ``r`` alone, so it changes only at the
    positions ``R`` that an atom whose cheapest or second cheapest cost or cheapest
    position changed had, before or after. Those columns are summed again over the atoms
    now at ``R`` in ascending order (the terms of a full sum, in its order); every other
    entry stays as it was.
    """
    m = ct.shape[0]
    moved = np.zeros(losses.shape[1], dtype=np.bool_)
    for j in range(m):
        if n1[j] != c1[j] or n2[j] != c2[j] or b1[j] != a1[j]:
            moved[a1[j]] = True
            moved[b1[j]] = True
    rows = np.flatnonzero(kept)
    columns = np.flatnonzero(moved)
    for i in rows:
        for r in columns:
            losses[i, r] = 0.0
    for j in range(m):
        owner = b1[j]
        if not moved[owner]:
            continue
        nearest, second, weight, costs = n1[j], n2[j], w[j], ct[j]
        for i in rows:
            fallback = min(costs[i], second) - nearest
            if fallback > 0.0:
                losses[i, owner] += weight * fallback


@njit(cache=True, nogil=True)
def fill_gains(
    c: FloatArray, w: FloatArray, c1: FloatArray, rows: IntArray, gains: FloatArray
) -> None:
    """``gains[i] = gain_i`` of the sites ``rows``, each summed as :func:`gain_of` sums it;
    four sites in one loop over ``j``. A term that is not negative adds ``+0.0``, which
    leaves every sum as it was."""
    m = c.shape[1]
    full = rows.size - rows.size % 4
    for k in range(0, full, 4):
        i0, i1, i2, i3 = rows[k], rows[k + 1], rows[k + 2], rows[k + 3]
        g0 = g1 = g2 = g3 = 0.0
        for j in range(m):
            nearest, weight = c1[j], w[j]
            d0 = c[i0, j] - nearest
            d1 = c[i1, j] - nearest
            d2 = c[i2, j] - nearest
            d3 = c[i3, j] - nearest
            g0 += weight * d0 if d0 < 0.0 else 0.0
            g1 += weight * d1 if d1 < 0.0 else 0.0
            g2 += weight * d2 if d2 < 0.0 else 0.0
            g3 += weight * d3 if d3 < 0.0 else 0.0
        gains[i0], gains[i1], gains[i2], gains[i3] = g0, g1, g2, g3
    for k in range(full, rows.size):
        gains[rows[k]] = gain_of(c, w, c1, rows[k])


@njit(cache=True, nogil=True)
def gain_of(c: FloatArray, w: FloatArray, c1: FloatArray, i: int) -> float:
    """``gain_i = sum_j w_j min(c_ij - c1_j, 0)``, summed over ``j`` in ascending order."""
    gain = 0.0
    for j in range(c.shape[1]):
        closer = c[i, j] - c1[j]
        if closer < 0.0:
            gain += w[j] * closer
    return gain


@njit(cache=True, nogil=True)
def relax_bounds(
    ct: FloatArray,
    w: FloatArray,
    bounds: FloatArray,
    exact: BoolArray,
    before: FloatArray,
    after: FloatArray,
) -> None:
    """Keep ``bounds`` lower bounds of the gains after the cheapest open costs went from
    ``before`` to ``after``.

    A term ``w_j min(c_ij - c1_j, 0)`` is ``0`` before and after where
    ``c_ij >= max(before_j, after_j)``: a site with no other term among the atoms whose
    ``c1_j`` changed keeps its gain (bit for bit, the same terms summed in the same
    order) and its bound. Elsewhere a term grows where ``c1_j`` falls and falls by at
    most ``w_j (after_j - before_j)`` where it rises, so the gain falls by at most
    ``rise = sum_j w_j max(after_j - before_j, 0)``; a relative ``1e-9`` more covers
    the rounding of the sums. ``ct`` is the cost matrix transposed (C-contiguous).
    """
    m, n = ct.shape
    rise = 0.0
    touched = np.zeros(n, dtype=np.bool_)
    for j in range(m):
        if after[j] == before[j]:
            continue
        if after[j] > before[j]:
            rise += w[j] * (after[j] - before[j])
        top = max(after[j], before[j])
        costs = ct[j]
        for i in range(n):
            if costs[i] < top:
                touched[i] = True
    for i in range(n):
        if touched[i]:
            exact[i] = False
            if math.isfinite(bounds[i]):
                bounds[i] -= rise + 1e-9 * (abs(bounds[i]) + rise)
