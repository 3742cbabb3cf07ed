"""The moves of a reference on the road network, written once for both update paths.

:class:`~routing_svc.network.space.RoadSpace` (the reference path of
:class:`~routing_svc.sa.Fleet`) and the compiled update
(:func:`~routing_svc.network.serving.serve_one`) both call these kernels, so a
fleet moves bit for bit the same either way.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from routing_svc.types import FloatArray, Int32Array, IntArray

__all__ = ["back_off_point", "branches", "entry_behind", "probe_point", "walk_one_edge"]

ENTRY_ON_ROUTE_START = 0
""":func:`entry_behind`: the new position is on the route's first edge."""
ENTRY_FOUND = 1
""":func:`entry_behind`: a junction farther than the window behind decides."""
ENTRY_WITHIN_WINDOW = 2
""":func:`entry_behind`: the whole route behind lies within the window."""


@njit(cache=True)
def probe_point(
    rate: FloatArray, window: float, edge: int, offset: float, entry_edge: int, entry_offset: float
) -> tuple[int, float]:
    """A reference's back probe: a cost ``window`` behind it on its edge when the offset
    allows, else its entry (``entry_edge < 0``: unknown, the start of its edge)."""
    edge_rate = rate[edge]
    if offset * edge_rate > window:
        return edge, offset - window / edge_rate
    if entry_edge >= 0:
        return entry_edge, entry_offset
    return edge, 0.0


@njit(cache=True)
def back_off_point(
    rate: FloatArray,
    edge: int,
    offset: float,
    probe_edge: int,
    probe_offset: float,
    amount: float,
) -> tuple[int, float]:
    """A reference moved a cost ``amount`` back toward its probe, never past it."""
    edge_rate = rate[edge]
    if probe_edge == edge:
        return edge, max(probe_offset, offset - amount / edge_rate)
    if amount >= offset * edge_rate:
        return probe_edge, probe_offset
    return edge, offset - amount / edge_rate


@njit(cache=True)
def walk_one_edge(
    rate: FloatArray, edge: int, offset: float, target_offset: float, spend: float
) -> tuple[bool, float]:
    """A cost ``spend`` driven toward a target ahead on the same ``edge``: whether it
    reaches the target, and the new offset."""
    edge_rate = rate[edge]
    if spend >= (target_offset - offset) * edge_rate:
        return True, target_offset
    return False, min(offset + spend / edge_rate, target_offset)


@njit(cache=True)
def branches(fwd_indptr: Int32Array, rev: IntArray, either_way: bool, edge: int) -> bool:
    """Whether a reference at the end of ``edge`` has a choice: two turns, or its twin."""
    turns = fwd_indptr[edge + 1] - fwd_indptr[edge]
    return turns > 1 or (either_way and rev[edge] >= 0)


@njit(cache=True)
def entry_behind(
    fwd_indptr: Int32Array,
    rev: IntArray,
    either_way: bool,
    length: FloatArray,
    cost: FloatArray,
    rate: FloatArray,
    route: IntArray,
    new_edge: int,
    new_offset: float,
    window: float,
) -> tuple[int, int]:
    """The junction behind a reference moved to ``(new_edge, new_offset)`` along ``route``.

    Walks the route back from the last place it reaches ``new_edge``: the farthest
    junction with a choice (:func:`branches`) within a cost ``window`` behind, else the
    nearest one beyond it. Returns ``(how, edge)``: :data:`ENTRY_ON_ROUTE_START` (the
    new position is on the route's first edge), :data:`ENTRY_FOUND` (``edge`` is the
    entry, at its end) or :data:`ENTRY_WITHIN_WINDOW` (``edge`` is the best candidate,
    ``-1`` for none, and the previous entry may still be within the window).
    """
    k = 0
    for j in range(route.shape[0] - 1, 0, -1):
        if route[j] == new_edge:
            k = j
            break
    if k == 0:
        return ENTRY_ON_ROUTE_START, -1
    behind = new_offset * rate[new_edge]
    best = -1
    for j in range(k - 1, -1, -1):
        edge = route[j]
        if branches(fwd_indptr, rev, either_way, edge) and (best < 0 or behind <= window):
            best = edge
        if behind > window and best >= 0:
            return ENTRY_FOUND, best
        behind += cost[edge]
    return ENTRY_WITHIN_WINDOW, best


NO_ROUTE = np.empty(0, dtype=np.int64)
"""The route of a move that had none (a back-off, a perturbation)."""
