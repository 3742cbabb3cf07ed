"""Compile a SUMO network into flat arrays of an edge-based graph.

The graph that every search runs on has one node per usable road edge (not an
internal ``:`` edge, open to the vehicle class) and one arc per pair of edges
joined by a SUMO connection that the vehicle class may use: a lane-to-lane
connection whose from-lane, to-lane and own permissions allow the class
(sumolib's ``Edge.getAllowedOutgoing``). Turn restrictions and one-way
streets are therefore honoured exactly as SUMO routes vehicles. The lengths of
internal junction lanes are not part of any cost.

Only the largest strongly connected component of that graph is kept, so that
every position can reach every other; :class:`NetworkReduction` says how many
usable edges that dropped.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from routing_svc.errors import InvalidInput, InvalidNetwork
from routing_svc.network.layout import (
    EndStateClasses,
    csr_from_arcs,
    end_state_classes,
    hilbert_order,
)
from routing_svc.network.projection import GeoProjection
from routing_svc.network.safe_xml import check_net_xml_file
from routing_svc.types import FloatArray, Int32Array

__all__ = ["CompiledNetwork", "NetworkReduction", "compile_network"]


@dataclass(frozen=True, slots=True)
class NetworkReduction:
    """What compiling a network kept and dropped.

    Attributes
    ----------
    usable_edges : int
        Non-internal edges open to the vehicle class.
    kept_edges : int
        Edges of the largest strongly connected component: the compiled network.
    dropped_edges : int
        ``usable_edges - kept_edges``: edges from which some other edge cannot
        be reached or that cannot be reached (or with unusable geometry).
    components : int
        Number of strongly connected components among the usable edges.
    """

    usable_edges: int
    kept_edges: int
    dropped_edges: int
    components: int


@dataclass(frozen=True, eq=False)
class CompiledNetwork:
    """A road network as an edge-based graph in flat arrays (immutable).

    Graph node ``i`` is the edge ``edge_ids[i]``; arrays are indexed by it.

    Attributes
    ----------
    vclass : str
        The SUMO vehicle class the graph was compiled for.
    source_sha256 : str
        The network's identity: SHA-256 of its plain XML
        (:func:`routing_svc.network.identity.network_sha256`).
    edge_ids : tuple[str, ...]
        SUMO edge id of every graph node.
    length : FloatArray
        Edge length in metres (SUMO's lane length), > 0.
    speed : FloatArray
        Free-flow speed in m/s: the largest speed limit of the edge's lanes
        open to the vehicle class, > 0.
    edge_from, edge_to : Int32Array
        Index into ``junction_ids`` of each edge's start and end junction.
    junction_ids : tuple[str, ...]
        Ids of the junctions that kept edges touch.
    fwd_indptr, fwd_indices : Int32Array
        CSR of successors: edges reachable from the end of edge ``i`` are
        ``fwd_indices[fwd_indptr[i]:fwd_indptr[i + 1]]``.
    rev_indptr, rev_indices : Int32Array
        CSR of predecessors (the reverse graph).
    shape_xy : FloatArray
        All edge shapes, shape ``(n_points, 2)``, network coordinates.
    shape_offsets : Int32Array
        Points of edge ``i`` are ``shape_xy[shape_offsets[i]:shape_offsets[i + 1]]``.
    bounds : tuple[float, float, float, float]
        ``(xmin, ymin, xmax, ymax)`` of the kept shapes.
    projection : GeoProjection | None
        The geographic projection, ``None`` when the network has none.
    reduction : NetworkReduction
        What compilation kept and dropped.
    """

    vclass: str
    source_sha256: str
    edge_ids: tuple[str, ...]
    length: FloatArray
    speed: FloatArray
    edge_from: Int32Array
    edge_to: Int32Array
    junction_ids: tuple[str, ...]
    fwd_indptr: Int32Array
    fwd_indices: Int32Array
    rev_indptr: Int32Array
    rev_indices: Int32Array
    shape_xy: FloatArray
    shape_offsets: Int32Array
    bounds: tuple[float, float, float, float]
    projection: GeoProjection | None
    reduction: NetworkReduction
    edge_index: Mapping[str, int] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "edge_index", {e: i for i, e in enumerate(self.edge_ids)})
        _validate(self)
        for name in _ARRAY_FIELDS:
            getattr(self, name).flags.writeable = False

    @property
    def n_edges(self) -> int:
        """Number of edges (graph nodes)."""
        return len(self.edge_ids)

    @cached_property
    def length_values(self) -> list[float]:
        """``length`` as a list of Python floats, for per-position checks in Python code
        (indexing a list is cheaper than indexing an array)."""
        return [float(v) for v in self.length.tolist()]

    @property
    def n_junctions(self) -> int:
        """Number of junctions that kept edges touch."""
        return len(self.junction_ids)

    @property
    def n_connections(self) -> int:
        """Number of arcs (usable connections between kept edges)."""
        return int(self.fwd_indices.shape[0])

    @cached_property
    def end_classes(self) -> EndStateClasses:
        """Edges grouped by successor set, the graph the nearest-vehicle search runs on.

        Derived from the successor lists on first use (not stored in the
        cache); see :func:`routing_svc.network.layout.end_state_classes`.
        """
        return end_state_classes(
            self.fwd_indptr, self.fwd_indices, self.rev_indptr, self.rev_indices
        )

    def arrays(self) -> dict[str, npt.NDArray[Any]]:
        """The numpy arrays of the network, by field name (what the cache stores)."""
        return {name: getattr(self, name) for name in _ARRAY_FIELDS}

    def nbytes(self) -> int:
        """Bytes held by the numpy arrays of the network, the end-state classes included."""
        return sum(a.nbytes for a in self.arrays().values()) + self.end_classes.nbytes()


_ARRAY_FIELDS = (
    "length",
    "speed",
    "edge_from",
    "edge_to",
    "fwd_indptr",
    "fwd_indices",
    "rev_indptr",
    "rev_indices",
    "shape_xy",
    "shape_offsets",
)


def _check_csr(indptr: Int32Array, indices: Int32Array, n: int, what: str) -> None:
    if indptr.shape != (n + 1,) or indptr[0] != 0 or indptr[-1] != indices.shape[0]:
        raise InvalidNetwork(f"{what}: inconsistent CSR offsets")
    if (np.diff(indptr) < 0).any() or indices.ndim != 1:
        raise InvalidNetwork(f"{what}: inconsistent CSR offsets")
    if indices.shape[0] and (indices.min() < 0 or indices.max() >= n):
        raise InvalidNetwork(f"{what}: edge index out of range")


def _validate(network: CompiledNetwork) -> None:
    """Raise :class:`InvalidNetwork` unless the arrays form a consistent graph.

    The compiled search indexes arrays without bounds checks, so a network
    (e.g. read back from a damaged cache) is checked before it is used.
    """
    n = len(network.edge_ids)
    if n == 0 or len(network.edge_index) != n:
        raise InvalidNetwork("a compiled network needs distinct edge ids")
    for name in ("length", "speed", "edge_from", "edge_to"):
        if getattr(network, name).shape != (n,):
            raise InvalidNetwork(f"{name}: one value per edge expected")
    if not (np.isfinite(network.length).all() and (network.length > 0).all()):
        raise InvalidNetwork("edge lengths must be finite and > 0")
    if not (np.isfinite(network.speed).all() and (network.speed > 0).all()):
        raise InvalidNetwork("edge speeds must be finite and > 0")
    ends = np.concatenate((network.edge_from, network.edge_to))
    if ends.min() < 0 or ends.max() >= len(network.junction_ids):
        raise InvalidNetwork("junction index out of range")
    _check_csr(network.fwd_indptr, network.fwd_indices, n, "successors")
    _check_csr(network.rev_indptr, network.rev_indices, n, "predecessors")
    fwd_tails = np.repeat(np.arange(n, dtype=np.int32), np.diff(network.fwd_indptr))
    rev_heads = np.repeat(np.arange(n, dtype=np.int32), np.diff(network.rev_indptr))
    fwd = np.sort(fwd_tails.astype(np.int64) * n + network.fwd_indices)
    rev = np.sort(network.rev_indices.astype(np.int64) * n + rev_heads)
    if fwd.shape != rev.shape or (fwd != rev).any():
        raise InvalidNetwork("predecessor lists are not the reverse of the successor lists")
    offsets, points = network.shape_offsets, network.shape_xy
    if points.ndim != 2 or points.shape[1] != 2 or not np.isfinite(points).all():
        raise InvalidNetwork("edge shapes must be finite (x, y) points")
    _check_csr(offsets, np.zeros(points.shape[0], dtype=np.int32), n, "shapes")
    if (np.diff(offsets) < 2).any():
        raise InvalidNetwork("every edge shape needs at least two points")


@dataclass(slots=True)
class _Edges:
    """Per-edge attributes read from sumolib, before the component filter."""

    ids: list[str]
    length: list[float]
    speed: list[float]
    from_node: list[str]
    to_node: list[str]
    shapes: list[list[tuple[float, float]]]


def _read_edges(net: Any, vclass: str) -> tuple[_Edges, list[Any], int]:
    """Usable edges with valid geometry, the sumolib edge objects, and the usable count."""
    edges = _Edges([], [], [], [], [], [])
    objects: list[Any] = []
    usable = 0
    for edge in net.getEdges():
        if edge.getID().startswith(":") or not edge.allows(vclass):
            continue
        usable += 1
        length = float(edge.getLength())
        speed = max(float(lane.getSpeed()) for lane in edge.getLanes() if lane.allows(vclass))
        shape = [(float(x), float(y)) for x, y in edge.getShape()]
        if not (math.isfinite(length) and length > 0 and math.isfinite(speed) and speed > 0):
            continue
        if len(shape) < 2 or not all(math.isfinite(x) and math.isfinite(y) for x, y in shape):
            continue
        objects.append(edge)
        edges.ids.append(edge.getID())
        edges.length.append(length)
        edges.speed.append(speed)
        edges.from_node.append(edge.getFromNode().getID())
        edges.to_node.append(edge.getToNode().getID())
        edges.shapes.append(shape)
    return edges, objects, usable


def _read_arcs(objects: list[Any], vclass: str) -> tuple[Int32Array, Int32Array]:
    """Tails and heads of the connections usable by ``vclass`` between ``objects``."""
    index = {edge.getID(): i for i, edge in enumerate(objects)}
    tails: list[int] = []
    heads: list[int] = []
    for i, edge in enumerate(objects):
        for to_edge in edge.getAllowedOutgoing(vclass):
            j = index.get(to_edge.getID())
            if j is not None:
                tails.append(i)
                heads.append(j)
    return np.asarray(tails, dtype=np.int32), np.asarray(heads, dtype=np.int32)


def _largest_component(tails: Int32Array, heads: Int32Array, n: int) -> tuple[Int32Array, int]:
    """Indices (ascending) of the largest strongly connected component, and the component count."""
    graph = csr_matrix((np.ones(tails.shape[0]), (tails, heads)), shape=(n, n))
    n_components, labels = connected_components(graph, directed=True, connection="strong")
    largest = int(np.argmax(np.bincount(labels)))
    return np.flatnonzero(labels == largest).astype(np.int32), int(n_components)


def _projection(net: Any) -> GeoProjection | None:
    if not net.hasGeoProj():
        return None
    offset = net.getLocationOffset()
    # sumolib exposes the PROJ string only through the parsed <location> attributes.
    return GeoProjection.parse(str(net._location["projParameter"]), (offset[0], offset[1]))


def compile_network(path: Path, *, vclass: str, source_sha256: str) -> CompiledNetwork:
    """Read a SUMO network with sumolib and compile it for one vehicle class.

    Parameters
    ----------
    path : Path
        A ``.net.xml`` or ``.net.xml.gz`` file.
    vclass : str
        SUMO vehicle class, e.g. ``"passenger"``.
    source_sha256 : str
        The network's identity (recorded in the result).

    Raises
    ------
    InvalidInput
        If ``vclass`` is not a SUMO vehicle class.
    InvalidNetwork
        If the file is hostile or malformed, no edge is usable, or no two usable edges
        reach each other (a fleet needs a loop to reach a target behind a vehicle).
    """
    import sumolib

    if vclass not in sumolib.net.lane.SUMO_VEHICLE_CLASSES:
        raise InvalidInput(f"unknown SUMO vehicle class {vclass!r}")
    check_net_xml_file(path)
    try:
        net = sumolib.net.readNet(str(path), withInternal=False, withConnections=True)
        edges, objects, usable = _read_edges(net, vclass)
        tails, heads = _read_arcs(objects, vclass)
        projection = _projection(net)
    except InvalidNetwork:
        raise
    except Exception as exc:  # sumolib raises bare KeyError/ValueError/... on bad content
        raise InvalidNetwork(f"cannot read network {path.name}: {exc!r}") from None
    if not objects:
        raise InvalidNetwork(f"network {path.name} has no edge open to vehicle class {vclass!r}")
    keep, n_components = _largest_component(tails, heads, len(objects))
    if keep.shape[0] == 1 and not np.any((tails == keep[0]) & (heads == keep[0])):
        raise InvalidNetwork(
            f"network {path.name} has no loop of edges open to vehicle class {vclass!r}: "
            "every edge is a way of no return (its largest strongly connected part is "
            f"one edge, among {n_components}), so no vehicle could reach a target behind it"
        )
    return _assemble(
        edges, tails, heads, keep, usable, n_components, vclass, source_sha256, projection
    )


def _assemble(
    edges: _Edges,
    tails: Int32Array,
    heads: Int32Array,
    keep: Int32Array,
    usable: int,
    n_components: int,
    vclass: str,
    source_sha256: str,
    projection: GeoProjection | None,
) -> CompiledNetwork:
    """Restrict the read edges and arcs to ``keep`` and lay them out as arrays.

    Kept edges are numbered along a Hilbert curve through their midpoints
    (see :mod:`routing_svc.network.layout`).
    """
    n = int(keep.shape[0])
    ends = np.array([(edges.shapes[i][0], edges.shapes[i][-1]) for i in keep.tolist()])
    keep = keep[hilbert_order(ends.mean(axis=1).reshape(n, 2))]
    new_index = np.full(len(edges.ids), -1, dtype=np.int32)
    new_index[keep] = np.arange(n, dtype=np.int32)
    both = (new_index[tails] >= 0) & (new_index[heads] >= 0)
    t, h = new_index[tails[both]], new_index[heads[both]]
    fwd_indptr, fwd_indices = csr_from_arcs(t, h, n)
    rev_indptr, rev_indices = csr_from_arcs(h, t, n)

    kept = keep.tolist()
    junctions: dict[str, int] = {}
    edge_from = np.array([junctions.setdefault(edges.from_node[i], len(junctions)) for i in kept])
    edge_to = np.array([junctions.setdefault(edges.to_node[i], len(junctions)) for i in kept])
    shapes = [edges.shapes[i] for i in kept]
    shape_offsets = np.zeros(n + 1, dtype=np.int32)
    np.cumsum([len(s) for s in shapes], out=shape_offsets[1:])
    shape_xy = np.array([p for s in shapes for p in s], dtype=np.float64).reshape(-1, 2)
    lo, hi = shape_xy.min(axis=0), shape_xy.max(axis=0)
    return CompiledNetwork(
        vclass=vclass,
        source_sha256=source_sha256,
        edge_ids=tuple(edges.ids[i] for i in kept),
        length=np.array([edges.length[i] for i in kept], dtype=np.float64),
        speed=np.array([edges.speed[i] for i in kept], dtype=np.float64),
        edge_from=edge_from.astype(np.int32),
        edge_to=edge_to.astype(np.int32),
        junction_ids=tuple(junctions),
        fwd_indptr=fwd_indptr,
        fwd_indices=fwd_indices,
        rev_indptr=rev_indptr,
        rev_indices=rev_indices,
        shape_xy=shape_xy,
        shape_offsets=shape_offsets,
        bounds=(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])),
        projection=projection,
        reduction=NetworkReduction(
            usable_edges=usable,
            kept_edges=n,
            dropped_edges=usable - n,
            components=n_components,
        ),
    )
