"""Leaving a reference position in either direction of a two-way street.

A vehicle waiting at its reference position ``(e, s)`` on a street that has
a reverse edge ``r`` (the edge between the same two junctions, the other way)
can turn around at the curb and leave along ``r`` from the matching point
``(r, L_r (1 - s / L_e))``: its *twin* position. Its cost to a target is the
smaller of the costs from the position and from its twin. This keeps the
expected service cost continuous along two-way streets, so the stochastic
gradient step (eq. (10)) can settle at a median instead of being dragged
forward along a one-directional lane; on one-way streets nothing changes.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from routing_svc.network.compile import CompiledNetwork
from routing_svc.types import FloatArray, IntArray, NetPosition


@functools.lru_cache(maxsize=32)
def reverse_edges(network: CompiledNetwork) -> IntArray:
    """``rev[e]``: the edge from ``to(e)`` to ``from(e)``, or ``-1`` when there is none.

    Where several edges join the same two junctions the lowest index is taken.
    """
    rev = np.full(network.n_edges, -1, dtype=np.int64)
    ends = list(zip(network.edge_from.tolist(), network.edge_to.tolist(), strict=True))
    by_ends: dict[tuple[int, int], int] = {}
    for e, (a, b) in enumerate(ends):
        by_ends.setdefault((a, b), e)
    for e, (a, b) in enumerate(ends):
        if a != b:
            rev[e] = by_ends.get((b, a), -1)
    rev.flags.writeable = False
    return rev


def twin_columns(
    network: CompiledNetwork, edges: IntArray, offsets: FloatArray
) -> tuple[IntArray, FloatArray]:
    """Twin edge and offset of each position (edge ``-1`` where there is no twin)."""
    rev = reverse_edges(network)[edges]
    has = rev >= 0
    safe = np.where(has, rev, 0)
    frac = 1.0 - offsets / network.length[edges]
    twin_offset = np.clip(frac * network.length[safe], 0.0, network.length[safe])
    return rev, np.where(has, twin_offset, 0.0)


def twin(network: CompiledNetwork, position: NetPosition) -> NetPosition | None:
    """The twin of one position, or ``None`` on a one-way street."""
    edges, offsets = twin_columns(
        network, np.array([position.edge], dtype=np.int64), np.array([position.offset])
    )
    if edges[0] < 0:
        return None
    return NetPosition(int(edges[0]), float(offsets[0]))


@njit(cache=True)
def set_twins(
    rev: IntArray, length: FloatArray, edges: IntArray, offsets: FloatArray, rows: IntArray
) -> None:
    """Write, in place, the twin entries ``n + i`` of the vehicle entries ``i`` in ``rows``
    of columns laid out as :func:`with_twins` lays them out (``2 n`` long).

    The twin's edge is ``-1`` where there is none: on a one-way street, or where the
    position itself is not on the network (the search then reports that vehicle).
    Twin offsets are those of :func:`twin_columns`.
    """
    n = edges.shape[0] // 2
    n_edges = length.shape[0]
    for i in rows:
        e = edges[i]
        s = offsets[i]
        r = -1
        if 0 <= e < n_edges and 0.0 <= s <= length[e]:
            r = rev[e]
        edges[n + i] = r
        if r >= 0:
            twin_length = length[r]
            at = (1.0 - s / length[e]) * twin_length
            offsets[n + i] = min(max(at, 0.0), twin_length)
        else:
            offsets[n + i] = 0.0


@njit(cache=True)
def with_twins(
    rev: IntArray, length: FloatArray, edges: IntArray, offsets: FloatArray
) -> tuple[IntArray, FloatArray]:
    """The vehicle columns followed by their twins, as the search takes them: entry
    ``n + i`` is the twin of vehicle ``i`` (see :func:`set_twins`)."""
    n = edges.shape[0]
    out_edges = np.empty(2 * n, dtype=np.int64)
    out_offsets = np.empty(2 * n)
    out_edges[:n] = edges
    out_offsets[:n] = offsets
    set_twins(rev, length, out_edges, out_offsets, np.arange(n))
    return out_edges, out_offsets
