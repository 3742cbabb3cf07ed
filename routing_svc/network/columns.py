"""The search's vehicle columns of position lists, kept up to date between searches.

:func:`~routing_svc.network.search.nearest_vehicles` takes a fleet as arrays:
edge indices and offsets, followed (with ``either_way``) by each vehicle's
twin (:func:`~routing_svc.network.twins.with_twins`). A fleet searches with
the same list of positions again and again, and between two searches only
the vehicle that moved (and any the backward probe moved) holds a new
position. :class:`SearchColumns` keeps the arrays of the lists it saw last
and rewrites only the entries whose position object changed, found by
identity, so that a search of an ``n``-vehicle fleet costs no ``O(n)``
Python work.

The arrays are exactly those that :func:`~routing_svc.network.search.fleet_columns`
and :func:`~routing_svc.network.twins.with_twins` build from the whole list: a changed
entry is converted as ``fleet_columns`` converts it, and its twin is written by
:func:`~routing_svc.network.twins.set_twins`, which ``with_twins`` uses too.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Sequence
from itertools import compress, count
from operator import is_not

import numpy as np

from routing_svc.network.compile import CompiledNetwork
from routing_svc.network.search import fleet_columns
from routing_svc.network.twins import reverse_edges, set_twins, with_twins
from routing_svc.types import FloatArray, IntArray, NetPosition

__all__ = ["SearchColumns", "changed_rows", "write_rows"]


class _Entry:
    """The columns of one list of positions and the position objects they were built from."""

    __slots__ = ("edges", "items", "offsets", "source")

    def __init__(
        self,
        source: list[NetPosition],
        items: list[NetPosition],
        edges: IntArray,
        offsets: FloatArray,
    ) -> None:
        self.source = source
        self.items = items
        self.edges = edges
        self.offsets = offsets


def changed_rows(current: Sequence[object], seen: Sequence[object]) -> list[int]:
    """The indices where ``current`` holds another object than ``seen`` (by identity, in C)."""
    return list(compress(count(), map(is_not, current, seen)))


def write_rows(
    network: CompiledNetwork,
    either_way: bool,
    positions: Sequence[NetPosition],
    rows: list[int],
    edges: IntArray,
    offsets: FloatArray,
) -> None:
    """Write ``positions[i]`` for ``i`` in ``rows`` into search columns (``2 n`` long with
    twins, as :func:`~routing_svc.network.twins.with_twins` lays them out), and their twins.

    Each position is converted as :func:`~routing_svc.network.search.fleet_columns`
    converts it; a bad one raises :class:`InvalidInput` before anything is written.
    """
    fresh: list[tuple[int, int, float]] = []
    for i in rows:
        e, s = positions[i]
        if type(e) is not int or type(s) is not float:
            column_edges, column_offsets = fleet_columns([positions[i]])  # or InvalidInput
            e, s = int(column_edges[0]), float(column_offsets[0])
        fresh.append((i, e, s))
    for i, e, s in fresh:
        edges[i] = e
        offsets[i] = s
    if either_way:
        indices = np.array(rows, dtype=np.int64)
        set_twins(reverse_edges(network), network.length, edges, offsets, indices)


class SearchColumns:
    """Edge and offset columns (with twins) of the position lists searched lately.

    Parameters
    ----------
    network : CompiledNetwork
        The network the positions are on.
    either_way : bool
        Append every vehicle's twin (:mod:`routing_svc.network.twins`).
    capacity : int
        How many lists are kept (the least recently searched one goes first).

    Notes
    -----
    A list is recognised by identity, and the entry keeps it alive, so the
    identity cannot pass to another list. The returned arrays belong to the
    cache: the search only reads them, and the caller must not keep them
    past its search. Entries of one list must not be used from two threads at
    once (a fleet searches under its lock); different lists may.
    """

    def __init__(self, network: CompiledNetwork, *, either_way: bool, capacity: int = 64) -> None:
        self._network = network
        self._either_way = either_way
        self._capacity = capacity
        self._entries: OrderedDict[int, _Entry] = OrderedDict()
        self._guard = threading.Lock()

    def of(self, positions: list[NetPosition]) -> tuple[IntArray, FloatArray]:
        """``(edges, offsets)`` of ``positions``, each of length ``2 n`` with twins.

        Raises
        ------
        InvalidInput
            If a position is not a pair of an integer edge index and a number
            (as :func:`~routing_svc.network.search.fleet_columns`).
        """
        key = id(positions)
        with self._guard:
            entry = self._entries.get(key)
            if entry is not None:
                self._entries.move_to_end(key)
        n = len(positions)
        if entry is None or entry.source is not positions or len(entry.items) != n:
            entry = self._build(positions)
            with self._guard:
                self._entries[key] = entry
                self._entries.move_to_end(key)
                while len(self._entries) > self._capacity:
                    self._entries.popitem(last=False)
            return entry.edges, entry.offsets
        changed = changed_rows(positions, entry.items)
        if changed:
            write_rows(
                self._network, self._either_way, positions, changed, entry.edges, entry.offsets
            )
            for i in changed:
                entry.items[i] = positions[i]
        return entry.edges, entry.offsets

    def _build(self, positions: list[NetPosition]) -> _Entry:
        edges, offsets = self._columns(positions)
        return _Entry(positions, list(positions), edges, offsets)

    def _columns(self, positions: list[NetPosition]) -> tuple[IntArray, FloatArray]:
        edges, offsets = fleet_columns(positions)
        if self._either_way and len(positions):
            net = self._network
            edges, offsets = with_twins(reverse_edges(net), net.length, edges, offsets)
        return edges, offsets
