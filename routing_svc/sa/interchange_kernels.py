"""Compiled kernels of the p-median heuristic: lazy greedy addition and one interchange pass.

Both work on a C-contiguous cost matrix ``c`` of shape ``(n_sites, n_demand)``
and weights ``w >= 0``, and read ``c`` one row at a time.

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
cheapest and second cheapest open cost of atom ``j``, a pass prices every swap
(open the closed site ``i``, close the site at position ``r``) as
``gain_i + loss_ir`` in one loop over ``j`` per closed site, with a
length-``p`` accumulator for ``loss_i.``; see :mod:`routing_svc.sa.interchange`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from routing_svc.types import BoolArray, FloatArray, IntArray

__all__ = ["best_swap", "lazy_greedy", "nearest_two"]


@njit(cache=True)
def lazy_greedy(c: FloatArray, w: FloatArray, p: int) -> IntArray:
    """The ``p`` sites of greedy addition, in the order they open."""
    n, m = c.shape
    picked = np.empty(p, dtype=np.int64)
    if p == 0:
        return picked
    first, lowest = 0, np.inf
    for i in range(n):
        total = 0.0
        for j in range(m):
            total += w[j] * c[i, j]
        if total < lowest:
            first, lowest = i, total
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


@njit(cache=True, inline="always")
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


@njit(cache=True)
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


@njit(cache=True)
def best_swap(
    c: FloatArray,
    w: FloatArray,
    is_open: BoolArray,
    c1: FloatArray,
    c2: FloatArray,
    a1: IntArray,
    p: int,
) -> tuple[int, int, float]:
    """The swap ``(enter, leave)`` of least ``gain_enter + loss_enter,leave`` and its change.

    Closed sites in ascending order, positions in ascending order, the first strict
    minimum kept (``np.argmin`` over the row-major ``(n_sites, p)`` matrix of changes).
    ``(-1, -1, inf)`` if every site is open.
    """
    n, m = c.shape
    loss = np.empty(p)
    enter, leave, best = -1, -1, np.inf
    for i in range(n):
        if is_open[i]:
            continue
        gain = 0.0
        loss[:] = 0.0
        for j in range(m):
            value = c[i, j]
            if value < c1[j]:
                gain += w[j] * (value - c1[j])
            else:
                fallback = min(value, c2[j]) - c1[j]
                if fallback > 0.0:
                    loss[a1[j]] += w[j] * fallback
        for r in range(p):
            delta = gain + loss[r]
            if delta < best:
                enter, leave, best = i, r, delta
    return enter, leave, best
