"""Edge costs of a road space and batch shortest-path costs between positions.

An edge's cost is its length (m) or its travel time (s); a part of an edge
costs in proportion to its length (``rate = cost / length`` per metre). The
cost between two positions is defined in :mod:`routing_svc.network.search`;
:func:`cost_matrix` computes it for many pairs with scipy's C Dijkstra.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np
from numba import njit

from routing_svc.errors import InvalidInput, UnknownEdge, Unreachable
from routing_svc.network.compile import CompiledNetwork
from routing_svc.network.heap import heap_pop, heap_push
from routing_svc.types import FloatArray, Int32Array, IntArray, NetPosition

__all__ = [
    "CostKind",
    "DistanceRows",
    "EdgeCosts",
    "check_position",
    "cost_matrix",
    "position_arrays",
    "position_columns",
]

CostKind = Literal["length", "time"]

_MATRIX_CELLS = 4_000_000
_ROW_MEMO_BYTES = 256 * 2**20
_ROWS_PER_THREAD = 16
"""Rows a thread computes at least, when the rows to compute are shared between two."""


@dataclass(frozen=True, eq=False)
class EdgeCosts:
    """Cost of traversing each edge, and cost per metre along it.

    Attributes
    ----------
    kind : {"length", "time"}
        Metres or seconds.
    cost : FloatArray
        Cost of the whole edge (> 0, finite).
    rate : FloatArray
        ``cost / length``: cost of one metre of the edge.
    """

    kind: CostKind
    cost: FloatArray
    rate: FloatArray

    @cached_property
    def rate_values(self) -> list[float]:
        """``rate`` as a list of Python floats, for per-position arithmetic in Python code."""
        return [float(v) for v in self.rate.tolist()]

    @classmethod
    def free_flow(cls, network: CompiledNetwork, kind: CostKind) -> EdgeCosts:
        """Lengths, or free-flow travel times ``length / speed``."""
        if kind == "length":
            cost = network.length.copy()
        elif kind == "time":
            cost = network.length / network.speed
        else:
            raise InvalidInput(f"cost must be 'length' or 'time', got {kind!r}")
        return cls._of(kind, cost, network.length)

    @classmethod
    def _of(cls, kind: CostKind, cost: FloatArray, length: FloatArray) -> EdgeCosts:
        rate = cost / length
        cost.flags.writeable = False
        rate.flags.writeable = False
        return cls(kind=kind, cost=cost, rate=rate)

    def with_travel_times(self, network: CompiledNetwork, times: Mapping[str, float]) -> EdgeCosts:
        """A copy with the travel times (s) of some edges replaced.

        Raises
        ------
        InvalidInput
            If the costs are lengths, or a time is not a finite number > 0.
        UnknownEdge
            If an edge id is not in the network.
        """
        if self.kind != "time":
            raise InvalidInput("travel times can only be replaced in a space with cost='time'")
        cost = self.cost.copy()
        for edge_id, value in times.items():
            index = network.edge_index.get(edge_id)
            if index is None:
                raise UnknownEdge(f"unknown edge {edge_id!r}")
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise InvalidInput(f"travel time of edge {edge_id!r} is not a number")
            if not (math.isfinite(value) and value > 0):
                raise InvalidInput(f"travel time of edge {edge_id!r} must be finite and > 0")
            cost[index] = float(value)
        return self._of("time", cost, network.length)


def check_position(network: CompiledNetwork, position: NetPosition, *, what: str) -> None:
    """Raise :class:`InvalidInput` unless ``position`` lies on the network."""
    edge, offset = position
    if (
        type(edge) is int
        and type(offset) is float
        and 0 <= edge < len(network.edge_ids)
        and 0.0 <= offset <= network.length_values[edge]  # false for NaN
    ):
        return
    if isinstance(edge, bool) or not isinstance(edge, int | np.integer):
        raise InvalidInput(f"{what}: edge index must be an integer")
    if not 0 <= edge < network.n_edges:
        raise InvalidInput(f"{what}: edge index {edge} out of range")
    if isinstance(offset, bool) or not isinstance(offset, int | float | np.integer | np.floating):
        raise InvalidInput(f"{what}: offset must be a number")
    if not (math.isfinite(offset) and 0.0 <= offset <= network.length[edge]):
        raise InvalidInput(
            f"{what}: offset {offset!r} not in [0, {network.length[edge]}] on edge "
            f"{network.edge_ids[edge]!r}"
        )


def position_columns(positions: Sequence[NetPosition], *, what: str) -> tuple[IntArray, FloatArray]:
    """Edge indices and offsets of ``positions`` as arrays, not yet checked against a network.

    Raises
    ------
    InvalidInput
        If a position is not a pair of an integer edge index and a number.
    """
    if len(positions) == 0:
        return np.empty(0, dtype=np.int64), np.empty(0)
    try:
        raw_edges, raw_offsets = zip(*positions, strict=True)
        edges = np.array(raw_edges)
        offsets = np.array(raw_offsets, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidInput(f"every {what} position must be a pair (edge index, offset)") from None
    if edges.dtype.kind not in "iu" or edges.ndim != 1 or offsets.ndim != 1:
        raise InvalidInput(f"every {what} position needs an integer edge index")
    return edges.astype(np.int64, copy=False), offsets


def position_arrays(
    network: CompiledNetwork, positions: Sequence[NetPosition], *, what: str
) -> tuple[IntArray, FloatArray]:
    """Edge indices and offsets of ``positions``, validated.

    Raises
    ------
    InvalidInput
        If a position is not on the network.
    """
    edges, offsets = position_columns(positions, what=what)
    bad = (edges < 0) | (edges >= network.n_edges)
    if not bad.any():
        bad = ~((offsets >= 0.0) & (offsets <= network.length[edges]))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        check_position(network, positions[i], what=f"{what} {i}")
    return edges, offsets


class DistanceRows:
    """Shortest-path rows from edge ends on one network under fixed edge costs, with a
    bounded memo.

    Row ``e`` holds the cost from the end of edge ``e`` to the start of every edge: the
    smallest Dijkstra distance (arc ``x -> y`` weighs ``cost[y]``) to one of its
    predecessors, ``inf`` for an edge without one. The rows of the most recently used
    source edges are kept, up to ``max_bytes``: consolidations and checked moves ask
    again and again for the rows of the same references and sites. Safe to share
    between threads.
    """

    def __init__(
        self, network: CompiledNetwork, costs: EdgeCosts, *, max_bytes: int = _ROW_MEMO_BYTES
    ) -> None:
        self.network = network
        self.costs = costs
        self._memo: OrderedDict[int, FloatArray] = OrderedDict()
        self._capacity = max_bytes // (8 * max(network.n_edges, 1))
        self._lock = threading.Lock()

    def __len__(self) -> int:
        """Rows held in the memo."""
        with self._lock:
            return len(self._memo)

    def rows(self, edges: IntArray) -> FloatArray:
        """The rows of ``edges``, shape ``(len(edges), n_edges)``."""
        return self.rows_at(edges, None)

    def rows_at(self, edges: IntArray, columns: IntArray | None) -> FloatArray:
        """The rows of ``edges`` at ``columns`` (every edge if ``None``), shape
        ``(len(edges), len(columns))``."""
        width = self.network.n_edges if columns is None else columns.shape[0]
        out = np.empty((edges.shape[0], width))
        missing: list[int] = []
        with self._lock:
            for k, edge in enumerate(edges.tolist()):
                row = self._memo.get(edge)
                if row is None:
                    missing.append(k)
                else:
                    self._memo.move_to_end(edge)
                    out[k] = row if columns is None else row[columns]
        if missing:
            found = self._to_starts(self._edge_end_rows(edges[missing]))
            out[missing] = found if columns is None else found[:, columns]
            if self._capacity == 0:
                return out
            with self._lock:
                for k, found_row in zip(missing, found, strict=True):
                    row = found_row.copy()  # the memo bounds whole rows, not views of a chunk
                    row.flags.writeable = False
                    self._memo[int(edges[k])] = row
                while len(self._memo) > self._capacity:
                    self._memo.popitem(last=False)
        return out

    def _edge_end_rows(self, sources: IntArray) -> FloatArray:
        """Costs from the end of each edge of ``sources`` to the end of every edge, the
        sources shared between two threads (:func:`_dijkstra_from_edge_ends` holds no GIL)."""
        network = self.network
        out = np.empty((sources.shape[0], network.n_edges))
        graph = (network.fwd_indptr, network.fwd_indices, self.costs.cost)
        half = sources.shape[0] // 2
        if half < _ROWS_PER_THREAD:
            _dijkstra_from_edge_ends(*graph, sources, out)
            return out
        with ThreadPoolExecutor(2) as pool:
            for done in [
                pool.submit(_dijkstra_from_edge_ends, *graph, sources[:half], out[:half]),
                pool.submit(_dijkstra_from_edge_ends, *graph, sources[half:], out[half:]),
            ]:
                done.result()
        return out

    def _to_starts(self, to_ends: FloatArray) -> FloatArray:
        """Distances to the ends of edges made distances to their starts."""
        out = np.empty_like(to_ends)
        _least_over_predecessors(to_ends, self.network.rev_indptr, self.network.rev_indices, out)
        return out


@njit(cache=True, nogil=True)
def _least_over_predecessors(
    to_ends: FloatArray, indptr: Int32Array, preds: Int32Array, out: FloatArray
) -> None:
    """``out[r, e]``: the least ``to_ends[r, p]`` over the predecessors ``p`` of edge ``e``
    (``preds[indptr[e]:indptr[e + 1]]``), ``inf`` for an edge without one."""
    for r in range(to_ends.shape[0]):
        row = to_ends[r]
        for e in range(out.shape[1]):
            least = np.inf
            for k in range(indptr[e], indptr[e + 1]):
                if row[preds[k]] < least:
                    least = row[preds[k]]
            out[r, e] = least


@njit(cache=True, nogil=True)
def _dijkstra_from_edge_ends(
    indptr: Int32Array, successors: Int32Array, cost: FloatArray, sources: IntArray, out: FloatArray
) -> None:
    """``out[r]``: Dijkstra costs from the end of edge ``sources[r]`` to the end of every
    edge, arc ``x -> y`` weighing ``cost[y]`` (``successors[indptr[x]:indptr[x + 1]]``);
    ``inf`` where none leads. An edge enters the heap again only when its cost improves,
    at most once per arc, so the heap holds at most one entry per arc and the source."""
    n = indptr.shape[0] - 1
    keys = np.empty(successors.shape[0] + 1)
    nodes = np.empty(successors.shape[0] + 1, dtype=np.int32)
    settled = np.zeros(n, dtype=np.bool_)
    for r in range(sources.shape[0]):
        dist = out[r]
        dist[:] = np.inf
        settled[:] = False
        source = sources[r]
        dist[source] = 0.0
        size = heap_push(keys, nodes, 0, 0.0, source)
        while size > 0:
            here, node = keys[0], nodes[0]
            size = heap_pop(keys, nodes, size)
            if settled[node]:
                continue
            settled[node] = True
            for k in range(indptr[node], indptr[node + 1]):
                nxt = successors[k]
                through = here + cost[nxt]
                if through < dist[nxt]:
                    dist[nxt] = through
                    size = heap_push(keys, nodes, size, through, nxt)


def cost_matrix(
    rows: DistanceRows,
    sources: tuple[IntArray, FloatArray],
    targets: tuple[IntArray, FloatArray],
) -> FloatArray:
    """Directed shortest-path costs from every source to every target position, on the
    network and under the edge costs of ``rows``.

    The cost from the end of each distinct source edge to the start of each target
    edge comes from ``rows``, a chunk of sources at a time; the parts along the
    source's and the target's edges are added.

    Parameters
    ----------
    rows : DistanceRows
        The network's shortest-path rows under its edge costs.
    sources, targets : tuple of arrays
        Edge indices and offsets of positions on the network
        (:func:`position_arrays`, which validates them).

    Returns
    -------
    FloatArray
        Shape ``(len(sources[0]), len(targets[0]))``.

    Raises
    ------
    Unreachable
        If some target cannot be reached from some source.
    """
    network, costs = rows.network, rows.costs
    src_edge, src_off = sources
    tgt_edge, tgt_off = targets
    out = np.empty((src_edge.shape[0], tgt_edge.shape[0]))
    if out.size == 0:
        return out
    uniq_src, src_row = np.unique(src_edge, return_inverse=True)
    uniq_tgt, tgt_col = np.unique(tgt_edge, return_inverse=True)
    chunk = max(1, _MATRIX_CELLS // max(network.n_edges, 1))
    to_start = np.empty((uniq_src.shape[0], uniq_tgt.shape[0]))
    for lo in range(0, uniq_src.shape[0], chunk):
        to_start[lo : lo + chunk] = rows.rows_at(uniq_src[lo : lo + chunk], uniq_tgt)
    rate = costs.rate
    leave = (network.length[src_edge] - src_off) * rate[src_edge]
    enter = tgt_off * rate[tgt_edge]
    _assemble(to_start, src_row, tgt_col, leave, enter, out)
    same_rows, same_cols = _same_edge_pairs(src_edge, src_off, tgt_edge, tgt_off)
    out[same_rows, same_cols] = (tgt_off[same_cols] - src_off[same_rows]) * rate[
        tgt_edge[same_cols]
    ]
    if not np.isfinite(to_start).all() and not np.isfinite(out).all():
        i, j = (int(v[0]) for v in np.nonzero(~np.isfinite(out)))
        raise Unreachable(f"target {j} cannot be reached from source {i}")
    return out


@njit(cache=True, nogil=True)
def _assemble(
    to_start: FloatArray,
    src_row: IntArray,
    tgt_col: IntArray,
    leave: FloatArray,
    enter: FloatArray,
    out: FloatArray,
) -> None:
    """``out[i, j] = (to_start[src_row[i], tgt_col[j]] + leave[i]) + enter[j]``."""
    for i in range(out.shape[0]):
        row = to_start[src_row[i]]
        for j in range(out.shape[1]):
            out[i, j] = (row[tgt_col[j]] + leave[i]) + enter[j]


def _same_edge_pairs(
    src_edge: IntArray, src_off: FloatArray, tgt_edge: IntArray, tgt_off: FloatArray
) -> tuple[IntArray, IntArray]:
    """Pairs ``(i, j)`` of a source ``i`` at or before target ``j`` on the same edge: the
    cost between them runs along that edge alone."""
    order = np.argsort(tgt_edge, kind="stable")
    by_edge = tgt_edge[order]
    first = np.searchsorted(by_edge, src_edge, side="left")
    counts = np.searchsorted(by_edge, src_edge, side="right") - first
    pair_rows = np.repeat(np.arange(src_edge.shape[0]), counts)
    within = np.arange(pair_rows.shape[0]) - np.repeat(np.cumsum(counts) - counts, counts)
    pair_cols = order[np.repeat(first, counts) + within]
    ahead = src_off[pair_rows] <= tgt_off[pair_cols]
    return pair_rows[ahead], pair_cols[ahead]
