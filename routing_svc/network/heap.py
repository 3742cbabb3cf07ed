"""A binary min-heap of (key, node) pairs in two preallocated arrays, for numba.

The nearest-vehicle search pushes a node again whenever its key improves and
skips stale entries when they surface ("lazy deletion"), so the arrays need
room for one entry per improvement: at most the number of arcs plus the
number of nodes.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

__all__ = ["heap_pop", "heap_push"]

FloatArray = npt.NDArray[np.float64]
Int32Array = npt.NDArray[np.int32]


@njit(cache=True, inline="always")
def heap_push(keys: FloatArray, nodes: Int32Array, size: int, key: float, node: int) -> int:
    """Add ``node`` with priority ``key`` to the heap of ``size`` entries; return the new size."""
    i = size
    while i > 0:
        parent = (i - 1) >> 1
        if keys[parent] <= key:
            break
        keys[i] = keys[parent]
        nodes[i] = nodes[parent]
        i = parent
    keys[i] = key
    nodes[i] = node
    return size + 1


@njit(cache=True, inline="always")
def heap_pop(keys: FloatArray, nodes: Int32Array, size: int) -> int:
    """Remove the root (the caller read ``keys[0]``, ``nodes[0]`` before); return the new size."""
    size -= 1
    key = keys[size]
    node = nodes[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and keys[child + 1] < keys[child]:
            child += 1
        if keys[child] >= key:
            break
        keys[i] = keys[child]
        nodes[i] = nodes[child]
        i = child
    keys[i] = key
    nodes[i] = node
    return size
