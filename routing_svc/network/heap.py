"""A 4-ary min-heap of (key, node) pairs in two preallocated arrays, for numba.

The nearest-vehicle search pushes a node again whenever its key improves and
skips stale entries when they surface ("lazy deletion"), so the arrays need
room for one entry per improvement: at most the number of arcs plus the
number of nodes.

Each entry has four children (``4 i + 1 .. 4 i + 4``): the heap is half as
deep as a binary one, and the four keys compared on the way down share a
cache line, which makes the search's pops cheaper on a large grid.
"""

from __future__ import annotations

from numba import njit

from routing_svc.types import FloatArray, Int32Array

__all__ = ["heap_pop", "heap_push"]


@njit(cache=True, inline="always")
def heap_push(keys: FloatArray, nodes: Int32Array, size: int, key: float, node: int) -> int:
    """Add ``node`` with priority ``key`` to the heap of ``size`` entries; return the new size."""
    i = size
    while i > 0:
        parent = (i - 1) >> 2
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
        first = 4 * i + 1
        if first >= size:
            break
        child = first
        smallest = keys[first]
        for c in range(first + 1, min(first + 4, size)):
            if keys[c] < smallest:
                smallest = keys[c]
                child = c
        if smallest >= key:
            break
        keys[i] = smallest
        nodes[i] = nodes[child]
        i = child
    keys[i] = key
    nodes[i] = node
    return size
