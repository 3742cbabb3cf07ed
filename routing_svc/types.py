"""Value types shared by every layer."""

from __future__ import annotations

from typing import NamedTuple


class NetPosition(NamedTuple):
    """A position on a road network: ``offset`` metres from the start of edge
    number ``edge`` (an index into the compiled network's edge arrays, never an
    internal ``:``-edge)."""

    edge: int
    offset: float


class PlanePosition(NamedTuple):
    """A point of the Euclidean plane."""

    x: float
    y: float
