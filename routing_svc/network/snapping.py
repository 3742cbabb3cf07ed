"""Map coordinates to positions on the road network and back.

SUMO draws an edge along its shape, whose geometric length usually differs a
little from the edge's length (the length SUMO drives and routes with).
Offsets along a shape are therefore rescaled: a point at geometric distance
``d`` along a shape of geometric length ``G`` is at offset ``d * L / G`` of an
edge of length ``L``, and back.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import shapely
from numba import njit

from routing_svc.errors import InvalidInput, OffNetwork
from routing_svc.network.compile import CompiledNetwork
from routing_svc.types import FloatArray, Int32Array, NetPosition

__all__ = ["Snapper", "point_on_edge", "points_on_edges"]


def point_on_edge(network: CompiledNetwork, edge: int, offset: float) -> tuple[float, float]:
    """Network coordinates of the point ``offset`` metres along ``edge``.

    Parameters
    ----------
    network : CompiledNetwork
        The network.
    edge : int
        Edge index.
    offset : float
        Offset in metres, ``0 <= offset <= length[edge]``.
    """
    return _point_on_shape(
        network.shape_xy,
        int(network.shape_offsets[edge]),
        int(network.shape_offsets[edge + 1]),
        float(network.length[edge]),
        float(offset),
    )


def points_on_edges(
    network: CompiledNetwork, edges: npt.NDArray[np.int64], offsets: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """:func:`point_on_edge` of every ``(edges[i], offsets[i])``, the same arithmetic.

    Parameters
    ----------
    network : CompiledNetwork
        The network.
    edges : ndarray of int64
        Edge indices.
    offsets : FloatArray
        Offsets in metres, ``0 <= offsets[i] <= length[edges[i]]``.
    """
    return _points_on_shapes(
        network.shape_xy,
        network.shape_offsets,
        network.length,
        np.ascontiguousarray(edges, dtype=np.int64),
        np.ascontiguousarray(offsets, dtype=np.float64),
    )


@njit(cache=True)
def _points_on_shapes(
    points: FloatArray,
    shape_offsets: Int32Array,
    length: FloatArray,
    edges: npt.NDArray[np.int64],
    offsets: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """:func:`_point_on_shape` of every edge and offset."""
    xs = np.empty(edges.size)
    ys = np.empty(edges.size)
    for i in range(edges.size):
        e = edges[i]
        xs[i], ys[i] = _point_on_shape(
            points, shape_offsets[e], shape_offsets[e + 1], length[e], offsets[i]
        )
    return xs, ys


@njit(cache=True)
def _point_on_shape(
    points: FloatArray, first: int, end: int, length: float, offset: float
) -> tuple[float, float]:
    """The point at ``offset * G / length`` along the polyline ``points[first:end]`` of
    geometric length ``G`` (linear interpolation on the segment that holds it)."""
    total = 0.0
    for i in range(first, end - 1):
        total += math.hypot(points[i + 1, 0] - points[i, 0], points[i + 1, 1] - points[i, 1])
    distance = offset * total / length
    walked = 0.0
    for i in range(first, end - 1):
        dx = points[i + 1, 0] - points[i, 0]
        dy = points[i + 1, 1] - points[i, 1]
        segment = math.hypot(dx, dy)
        if segment > 0.0 and walked + segment >= distance:
            share = max(0.0, distance - walked) / segment
            return points[i, 0] + share * dx, points[i, 1] + share * dy
        walked += segment
    return points[end - 1, 0], points[end - 1, 1]


def _coordinate_arrays(
    a: npt.ArrayLike, b: npt.ArrayLike, *, names: str
) -> tuple[FloatArray, FloatArray]:
    """Two equally long 1-d arrays of finite floats, or :class:`InvalidInput`."""
    try:
        first = np.atleast_1d(np.asarray(a, dtype=np.float64))
        second = np.atleast_1d(np.asarray(b, dtype=np.float64))
    except (TypeError, ValueError):
        raise InvalidInput(f"{names} must be sequences of numbers") from None
    if first.shape != second.shape or first.ndim != 1:
        raise InvalidInput(f"{names} must be 1-d sequences of the same length")
    if not (np.isfinite(first).all() and np.isfinite(second).all()):
        raise InvalidInput(f"{names} must be finite numbers")
    return first, second


class Snapper:
    """Nearest positions on the network to coordinates, via a shapely ``STRtree``.

    Parameters
    ----------
    network : CompiledNetwork
        The network whose edge shapes are indexed.

    Notes
    -----
    The tree is built on first use. When several edges are equally near a
    point (e.g. at a shared junction corner), the lowest edge index wins.
    """

    def __init__(self, network: CompiledNetwork) -> None:
        self.network = network
        self._lines: npt.NDArray[np.object_] | None = None
        self._tree: shapely.STRtree | None = None
        self._geometric_length: FloatArray | None = None

    def _index(self) -> tuple[npt.NDArray[np.object_], shapely.STRtree, FloatArray]:
        if self._lines is None or self._tree is None or self._geometric_length is None:
            net = self.network
            owner = np.repeat(np.arange(net.n_edges), np.diff(net.shape_offsets))
            self._lines = shapely.linestrings(net.shape_xy, indices=owner)
            self._tree = shapely.STRtree(self._lines)
            self._geometric_length = shapely.length(self._lines)
        return self._lines, self._tree, self._geometric_length

    def snap_xy(
        self,
        xs: npt.ArrayLike,
        ys: npt.ArrayLike,
        *,
        max_distance: float | None = None,
    ) -> list[NetPosition]:
        """Nearest network position to each point ``(xs[i], ys[i])``.

        Parameters
        ----------
        xs, ys : array_like
            Network coordinates (metres), same length.
        max_distance : float, optional
            Points farther than this from every edge are rejected.

        Returns
        -------
        list[NetPosition]
            One position per point.

        Raises
        ------
        InvalidInput
            If a coordinate is not finite, the arrays differ in shape, or
            ``max_distance`` is not a finite number > 0.
        OffNetwork
            If a point is farther than ``max_distance`` from every edge.
        """
        x, y = _coordinate_arrays(xs, ys, names="xs and ys")
        if max_distance is not None and not (math.isfinite(max_distance) and max_distance > 0):
            raise InvalidInput("max_distance must be a finite number > 0")
        if x.shape[0] == 0:
            return []
        lines, tree, geometric_length = self._index()
        points = shapely.points(x, y)
        (query, edge), _ = tree.query_nearest(
            points, max_distance=max_distance, return_distance=True, all_matches=True
        )
        order = np.lexsort((edge, query))
        query, edge = query[order], edge[order]
        first = np.ones(query.shape[0], dtype=bool)
        first[1:] = query[1:] != query[:-1]
        query, edge = query[first], edge[first]
        if query.shape[0] != x.shape[0]:
            missing = np.setdiff1d(np.arange(x.shape[0]), query)
            raise OffNetwork(
                f"{missing.shape[0]} point(s) farther than {max_distance} m from every usable "
                f"edge, e.g. ({x[missing[0]]}, {y[missing[0]]})"
            )
        along = shapely.line_locate_point(lines[edge], points)
        length = self.network.length[edge]
        geo = geometric_length[edge]
        scale = np.divide(length, geo, out=np.zeros_like(length), where=geo > 0)
        offsets = np.clip(along * scale, 0.0, length)
        return [NetPosition(int(e), float(s)) for e, s in zip(edge, offsets, strict=True)]

    def snap_lonlat(
        self,
        lons: npt.ArrayLike,
        lats: npt.ArrayLike,
        *,
        max_distance: float | None = None,
    ) -> list[NetPosition]:
        """Nearest network position to each geographic point (WGS84 degrees).

        Raises
        ------
        InvalidInput
            If the network has no (supported) geographic projection, or a
            coordinate is not finite.
        OffNetwork
            If a point is farther than ``max_distance`` metres from every edge.
        """
        projection = self.network.projection
        if projection is None:
            raise InvalidInput("the network has no geographic projection")
        lon, lat = _coordinate_arrays(lons, lats, names="lons and lats")
        if (np.abs(lat) > 90).any():
            raise InvalidInput("latitudes must lie in [-90, 90]")
        x, y = projection.to_xy(lon, lat)
        return self.snap_xy(x, y, max_distance=max_distance)
