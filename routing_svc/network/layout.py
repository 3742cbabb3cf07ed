"""Memory layout of the compiled graph: edge numbering and CSR adjacency.

Edges are numbered along a Hilbert curve through their midpoints, so that
edges near each other on the map are near each other in memory. A search
from a target touches a compact region of the map; with this numbering it
also touches a compact region of every per-edge array, which makes the
nearest-vehicle search on large networks markedly faster (SUMO files list
edges by id, which is spatially random for imported maps).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["csr_from_arcs", "hilbert_order"]

FloatArray = npt.NDArray[np.float64]
Int32Array = npt.NDArray[np.int32]
Int64Array = npt.NDArray[np.int64]

_HILBERT_BITS = 16


def hilbert_keys(x: Int64Array, y: Int64Array, *, bits: int = _HILBERT_BITS) -> Int64Array:
    """Distance along the Hilbert curve of order ``bits`` of integer points in ``[0, 2**bits)``.

    Parameters
    ----------
    x, y : Int64Array
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


def hilbert_order(points: FloatArray) -> Int64Array:
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
