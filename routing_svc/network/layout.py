"""Memory layout of the compiled graph: edge numbering, CSR adjacency, end-state classes.

Edges are numbered along a Hilbert curve through their midpoints, so that
edges near each other on the map are near each other in memory. A search
from a target touches a compact region of the map; with this numbering it
also touches a compact region of every per-edge array, which makes the
nearest-vehicle search on large networks markedly faster (SUMO files list
edges by id, which is spatially random for imported maps).

End-state classes
-----------------
The cost from the *end* of an edge to any target depends only on the set of
edges a vehicle may take next there. Edges with the same successor set (for
instance all edges into a junction that allows every turn, U-turns
included) form one *end-state class*; the nearest-vehicle search runs its
Dijkstra over these classes instead of over edges, which is exact and, on a
grid from ``netgenerate``, a quarter of the nodes (one class per junction).
On networks with turn restrictions fewer edges share a class; the search stays
exact either way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from routing_svc.types import FloatArray, Int32Array, IntArray

__all__ = ["EndStateClasses", "csr_from_arcs", "end_state_classes", "hilbert_order"]


_HILBERT_BITS = 16


def hilbert_keys(x: IntArray, y: IntArray, *, bits: int = _HILBERT_BITS) -> IntArray:
    """Distance along the Hilbert curve of order ``bits`` of integer points in ``[0, 2**bits)``.

    Parameters
    ----------
    x, y : IntArray
        Integer coordinates.
    bits : int
        Order of the curve.
    """
    x = x.astype(np.int64, copy=True)
    y = y.astype(np.int64, copy=True)
    keys = np.zeros(x.shape, dtype=np.int64)
    side = 1 << (bits - 1)
    while side > 0:
        rx = (x & side) > 0
        ry = (y & side) > 0
        keys += side * side * ((3 * rx.astype(np.int64)) ^ ry.astype(np.int64))
        flip = ~ry & rx
        x[flip] = side - 1 - x[flip]
        y[flip] = side - 1 - y[flip]
        swap = ~ry
        x[swap], y[swap] = y[swap], x[swap].copy()
        side >>= 1
    return keys


def hilbert_order(points: FloatArray) -> IntArray:
    """Indices that sort ``points`` (shape ``(n, 2)``) along a Hilbert curve (stable)."""
    if points.shape[0] == 0:
        return np.empty(0, dtype=np.int64)
    lo = points.min(axis=0)
    span = float((points.max(axis=0) - lo).max())
    scale = ((1 << _HILBERT_BITS) - 1) / span if span > 0 else 0.0
    cells = np.floor((points - lo) * scale).astype(np.int64)
    return np.argsort(hilbert_keys(cells[:, 0], cells[:, 1]), kind="stable")


def csr_from_arcs(tails: Int32Array, heads: Int32Array, n: int) -> tuple[Int32Array, Int32Array]:
    """CSR ``(indptr, indices)`` listing the heads of the arcs leaving each node.

    Parameters
    ----------
    tails, heads : Int32Array
        Arc ``k`` goes from ``tails[k]`` to ``heads[k]``.
    n : int
        Number of nodes.

    Returns
    -------
    indptr, indices : Int32Array
        Heads of node ``i``'s arcs are ``indices[indptr[i]:indptr[i + 1]]``, ascending.
    """
    order = np.lexsort((heads, tails))
    indptr = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(np.bincount(tails, minlength=n), out=indptr[1:])
    return indptr, heads[order].astype(np.int32)


@dataclass(frozen=True, eq=False)
class EndStateClasses:
    """The edges of a graph grouped by successor set, and the arcs between the groups.

    Attributes
    ----------
    edge_class : Int32Array
        Class of every edge: edges of one class have the same successor set.
        Classes are numbered in the order of their lowest edge, so they keep
        the edges' memory locality.
    arc_indptr : Int32Array
        CSR offsets over classes, length ``n_classes + 1``.
    arc_edge, arc_class : Int32Array
        The arcs of the reverse class graph: for class ``c``, arc ``a`` in
        ``arc_indptr[c]:arc_indptr[c + 1]`` says that edge ``arc_edge[a]``
        (an edge of class ``c``, i.e. one whose end state is ``c``) is a
        successor of the edges of class ``arc_class[a]``. Every pair
        ``(edge, class of a predecessor)`` appears once, sorted by edge, then
        class.
    """

    edge_class: Int32Array
    arc_indptr: Int32Array
    arc_edge: Int32Array
    arc_class: Int32Array

    @property
    def n_classes(self) -> int:
        """Number of classes."""
        return int(self.arc_indptr.shape[0] - 1)

    def nbytes(self) -> int:
        """Bytes held by the arrays."""
        arrays = (self.edge_class, self.arc_indptr, self.arc_edge, self.arc_class)
        return sum(a.nbytes for a in arrays)


def _row_of(indptr: Int32Array) -> Int32Array:
    """Row of every CSR entry."""
    n = indptr.shape[0] - 1
    rows: Int32Array = np.repeat(np.arange(n, dtype=np.int32), np.diff(indptr))
    return rows


def _rows_ascending(indptr: Int32Array, indices: Int32Array) -> bool:
    """Whether every CSR row is strictly ascending."""
    if indices.shape[0] < 2:
        return True
    up = np.diff(indices) > 0
    starts = indptr[1:-1]
    starts = starts[(starts > 0) & (starts < indices.shape[0])]
    up[starts - 1] = True  # a new row may start lower
    return bool(up.all())


def _same_rows(indptr: Int32Array, indices: Int32Array, labels: IntArray, first: IntArray) -> bool:
    """Whether every row equals the row of ``first[labels[row]]`` (rows sorted ascending)."""
    degree = np.diff(indptr)
    rep = first[labels]
    if (degree != degree[rep]).any():
        return False
    shift = (indptr[:-1][rep] - indptr[:-1]).astype(np.int32)
    other = np.arange(indices.shape[0], dtype=np.int32)
    other += shift[_row_of(indptr)]
    return bool((indices == indices[other]).all())


def _exact_labels(indptr: Int32Array, indices: Int32Array) -> IntArray:
    """Label rows by content, exactly (``np.unique`` over the rows of each degree)."""
    n = indptr.shape[0] - 1
    degree = np.diff(indptr)
    labels = np.empty(n, dtype=np.int64)
    base = 0
    for d in np.unique(degree).tolist():
        members = np.flatnonzero(degree == d)
        if d == 0:
            labels[members] = base
            base += 1
            continue
        rows = indices[indptr[members][:, None] + np.arange(d)[None, :]]
        _, inverse = np.unique(rows, axis=0, return_inverse=True)
        labels[members] = inverse.reshape(-1) + base
        base += int(inverse.max()) + 1
    return labels


def _row_labels(indptr: Int32Array, indices: Int32Array) -> IntArray:
    """Equal labels for equal rows (rows sorted ascending), numbered by first row.

    Rows are hashed (a sum of fixed random 64-bit words, one per column),
    grouped by hash, and the grouping is verified row by row; on a hash
    collision the exact but slower labelling is used instead.
    """
    n = indptr.shape[0] - 1
    words = (
        np.random.default_rng(0x5EED)
        .integers(0, np.iinfo(np.int64).max, size=n, dtype=np.int64, endpoint=True)
        .view(np.uint64)
    )
    with np.errstate(over="ignore"):
        running = np.zeros(indices.shape[0] + 1, dtype=np.uint64)
        np.cumsum(words[indices], out=running[1:])
        hashes = running[indptr[1:]] - running[indptr[:-1]]
        hashes += np.diff(indptr).astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    order = np.argsort(hashes, kind="stable")
    ordered = hashes[order]
    starts = np.flatnonzero(np.concatenate(([True], ordered[1:] != ordered[:-1])))
    first = order[starts]
    labels = np.empty(n, dtype=np.int64)
    labels[order] = np.cumsum(np.concatenate(([True], ordered[1:] != ordered[:-1]))) - 1
    if not _same_rows(indptr, indices, labels, first):
        labels = _exact_labels(indptr, indices)
        first = np.full(int(labels.max()) + 1, n, dtype=np.int64)
        np.minimum.at(first, labels, np.arange(n, dtype=np.int64))
    rank = np.empty(first.shape[0], dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(first.shape[0], dtype=np.int64)
    result: IntArray = rank[labels]
    return result


def end_state_classes(
    fwd_indptr: Int32Array,
    fwd_indices: Int32Array,
    rev_indptr: Int32Array,
    rev_indices: Int32Array,
) -> EndStateClasses:
    """Group edges by successor set and build the reverse graph between the groups.

    Parameters
    ----------
    fwd_indptr, fwd_indices : Int32Array
        CSR of successors.
    rev_indptr, rev_indices : Int32Array
        CSR of predecessors (the same arcs, reversed).

    Returns
    -------
    EndStateClasses
        The classes and the arcs between them (read-only arrays).
    """
    n = fwd_indptr.shape[0] - 1
    ascending = fwd_indices
    if not _rows_ascending(fwd_indptr, fwd_indices):
        ascending = fwd_indices[np.lexsort((fwd_indices, _row_of(fwd_indptr)))]
    labels = _row_labels(fwd_indptr, ascending)
    n_classes = int(labels.max()) + 1 if n else 0
    keys = _row_of(rev_indptr).astype(np.int64)
    keys *= n_classes
    keys += labels[rev_indices]
    keys = np.sort(keys, kind="stable")
    if keys.shape[0] > 1:
        keys = keys[np.concatenate(([True], keys[1:] != keys[:-1]))]
    arc_edge = keys // max(n_classes, 1)
    arc_class = keys - arc_edge * n_classes
    owner = labels[arc_edge]
    order = np.argsort(owner, kind="stable")
    arc_indptr = np.zeros(n_classes + 1, dtype=np.int32)
    np.cumsum(np.bincount(owner, minlength=n_classes), out=arc_indptr[1:])
    classes = EndStateClasses(
        edge_class=labels.astype(np.int32),
        arc_indptr=arc_indptr,
        arc_edge=arc_edge[order].astype(np.int32),
        arc_class=arc_class[order].astype(np.int32),
    )
    for array in (classes.edge_class, classes.arc_indptr, classes.arc_edge, classes.arc_class):
        array.flags.writeable = False
    return classes
