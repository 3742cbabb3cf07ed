"""Value types shared by every layer."""

from __future__ import annotations

from typing import NamedTuple, TypeAlias

import numpy as np
import numpy.typing as npt

#: Arrays of the compiled network, the demand and the SA core.
FloatArray: TypeAlias = npt.NDArray[np.float64]
IntArray: TypeAlias = npt.NDArray[np.int64]
Int32Array: TypeAlias = npt.NDArray[np.int32]
BoolArray: TypeAlias = npt.NDArray[np.bool_]


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
