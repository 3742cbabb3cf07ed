"""Demand distributions on a road network.

Every constructor cuts each edge into ``k = ceil(length / spacing)`` equal
pieces and puts one atom at the middle of each piece; the atom carries the
demand of its piece (default spacing 20 m).

- :func:`uniform_by_length`: demand per metre of road is constant, so an
  atom's mass is its piece length.
- :func:`hotspot_mixture`: demand per metre follows an isotropic Gaussian
  mixture of the atom's coordinates (mass = piece length x density).
- :func:`from_weights_file`: a weight per edge, spread uniformly along it
  (:func:`from_edge_weights` for weights already in memory).
- :func:`from_buildings_file`: a weight per building on its nearest road,
  summed per edge and spread the same way.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from routing_svc.demand.buildings import read_building_weights
from routing_svc.demand.distribution import DemandDistribution
from routing_svc.demand.plane import mixture_density
from routing_svc.demand.weights_file import read_edge_weights
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork
from routing_svc.network.snapping import point_on_edge
from routing_svc.types import FloatArray, IntArray, NetPosition

_LOG = logging.getLogger("routing_svc.demand")

#: Default largest piece of road represented by one atom, in metres.
DEFAULT_SPACING = 20.0

#: Default hotspot standard deviation as a fraction of the network's bounding-box diagonal.
DEFAULT_SPREAD_FRACTION = 0.1


def uniform_by_length(
    network: CompiledNetwork, *, spacing: float = DEFAULT_SPACING
) -> DemandDistribution[NetPosition]:
    """Demand spread uniformly over the length of every road.

    Parameters
    ----------
    network : CompiledNetwork
        The road network; every edge carries demand.
    spacing : float
        Largest piece of road per atom, metres (``> 0``).

    Returns
    -------
    DemandDistribution
        Atoms at piece midpoints, weight proportional to piece length.
    """
    edges, offsets, pieces = edge_pieces(network, spacing=spacing)
    return DemandDistribution.from_masses(
        f"uniform_by_length:{spacing:g}m", _positions(edges, offsets), pieces
    )


def hotspot_mixture(
    network: CompiledNetwork,
    *,
    centres: Sequence[tuple[float, float]] | int = 3,
    spread: float | None = None,
    weights: Sequence[float] | None = None,
    rng: np.random.Generator | None = None,
    spacing: float = DEFAULT_SPACING,
) -> DemandDistribution[NetPosition]:
    """Demand concentrated around hotspots (a Gaussian mixture in x, y).

    Parameters
    ----------
    network : CompiledNetwork
        The road network.
    centres : sequence of (x, y) or int
        Hotspot centres in network coordinates, or how many to draw: ``K``
        centres are then the midpoints of ``K`` distinct road pieces drawn
        with probability proportional to length, using ``rng``.
    spread : float, optional
        Standard deviation of every hotspot, metres; default 10 % of the
        diagonal of the network's bounding box.
    weights : sequence of float, optional
        Relative weight of every hotspot; equal if omitted.
    rng : numpy.random.Generator, optional
        Required when ``centres`` is a count.
    spacing : float
        Largest piece of road per atom, metres.

    Returns
    -------
    DemandDistribution
        Atoms at piece midpoints with mass ``piece length x density(x, y)``.

    Raises
    ------
    InvalidInput
        A count without ``rng``, a count out of range, or bad centres, spread
        or weights (see :func:`~routing_svc.demand.plane.mixture_density`).
    """
    edges, offsets, pieces = edge_pieces(network, spacing=spacing)
    xy = positions_xy(network, edges, offsets)
    if isinstance(centres, int) and not isinstance(centres, bool):
        if rng is None:
            raise InvalidInput("drawing hotspot centres needs a numpy Generator (rng)")
        if not 1 <= centres <= len(pieces):
            raise InvalidInput(f"hotspot count must be between 1 and {len(pieces)}, got {centres}")
        picks = rng.choice(len(pieces), size=centres, replace=False, p=pieces / pieces.sum())
        chosen = [(float(xy[i, 0]), float(xy[i, 1])) for i in picks]
    elif isinstance(centres, bool):
        raise InvalidInput("hotspot centres must be a count or a list of (x, y)")
    else:
        chosen = [(float(x), float(y)) for x, y in centres]
    if spread is None:
        xmin, ymin, xmax, ymax = network.bounds
        spread = DEFAULT_SPREAD_FRACTION * max(math.hypot(xmax - xmin, ymax - ymin), 1.0)
    density = mixture_density(xy, centres=chosen, spread=spread, weights=weights)
    return DemandDistribution.from_masses(
        f"hotspots:{len(chosen)}", _positions(edges, offsets), pieces * density
    )


def from_weights_file(
    network: CompiledNetwork, path: str | Path, *, spacing: float = DEFAULT_SPACING
) -> DemandDistribution[NetPosition]:
    """Demand given as a weight per SUMO edge id, uniform along each edge.

    Parameters
    ----------
    network : CompiledNetwork
        The road network; edge ids are looked up in ``network.edge_index``.
    path : str or Path
        CSV (``edge_id,weight`` lines) or JSON (``{"edge_id": weight}``); see
        :mod:`routing_svc.demand.weights_file`.
    spacing : float
        Largest piece of road per atom, metres.

    Returns
    -------
    DemandDistribution
        Edge ``e`` of weight ``W_e`` gets atoms of mass ``W_e x piece / length_e``.

    Raises
    ------
    InvalidInput
        Any problem with the file, naming the line or key.
    """
    edge_weights = read_edge_weights(path, known_edges=network.edge_index)
    return from_edge_weights(
        network, edge_weights, name=f"weights_file:{Path(path).name}", spacing=spacing
    )


def from_buildings_file(
    network: CompiledNetwork, path: str | Path, *, spacing: float = DEFAULT_SPACING
) -> DemandDistribution[NetPosition]:
    """Demand from a buildings CSV: each building's ``Weight`` on its ``GenEdge``.

    The weights of an edge's buildings add up and are spread uniformly along
    the edge (:func:`from_edge_weights`). Buildings on edges outside the
    network are dropped and reported with a warning on the
    ``routing_svc.demand`` logger (see :mod:`routing_svc.demand.buildings`).

    Raises
    ------
    InvalidInput
        Any problem with the file, or no building left on the network.
    """
    found = read_building_weights(path, known_edges=network.edge_index)
    if found.dropped_buildings:
        _LOG.warning(
            "%s: %d of %d buildings (%.1f %% of the weight) are on %d edges outside the "
            "network's car component and were dropped",
            Path(path).name,
            found.dropped_buildings,
            found.buildings,
            100.0 * found.dropped_weight,
            len(found.dropped_edges),
        )
    return from_edge_weights(
        network, found.edge_weights, name=f"buildings:{Path(path).name}", spacing=spacing
    )


def from_edge_weights(
    network: CompiledNetwork,
    edge_weights: Mapping[int, float],
    *,
    name: str,
    spacing: float = DEFAULT_SPACING,
) -> DemandDistribution[NetPosition]:
    """Demand with weight ``W_e`` per edge index, spread uniformly along each edge.

    Raises
    ------
    InvalidInput
        No edge of positive weight, or weights that are not finite and ``>= 0``.
    """
    per_metre = np.zeros(network.n_edges)
    for edge, weight in edge_weights.items():
        per_metre[edge] = float(weight) / float(network.length[edge])
    carrying = np.flatnonzero(per_metre > 0.0)
    if carrying.size == 0:
        raise InvalidInput(f"demand {name!r} gives no edge a positive weight")
    edges, offsets, pieces = edge_pieces(network, spacing=spacing, edges=carrying)
    return DemandDistribution.from_masses(
        name, _positions(edges, offsets), pieces * per_metre[edges]
    )


def piece_counts(lengths: FloatArray, spacing: float) -> IntArray:
    """How many equal pieces of at most ``spacing`` metres each edge length is cut into
    (at least one)."""
    return np.maximum(1, np.ceil(lengths / spacing)).astype(np.int64)


def edge_pieces(
    network: CompiledNetwork, *, spacing: float, edges: IntArray | None = None
) -> tuple[IntArray, FloatArray, FloatArray]:
    """Cut edges into pieces of at most ``spacing`` metres.

    Parameters
    ----------
    network : CompiledNetwork
        The road network.
    spacing : float
        Largest piece length, metres (finite, ``> 0``).
    edges : IntArray, optional
        Edge indices to cut (default: all, in index order).

    Returns
    -------
    tuple of arrays
        Edge index, midpoint offset and length of every piece; the pieces of
        an edge are consecutive and ordered by offset.
    """
    if isinstance(spacing, bool) or not math.isfinite(spacing) or spacing <= 0.0:
        raise InvalidInput(f"spacing must be a finite number of metres > 0, got {spacing!r}")
    chosen = np.arange(network.n_edges) if edges is None else np.asarray(edges, dtype=np.int64)
    length = network.length[chosen]
    count = piece_counts(length, spacing)
    edge_of = np.repeat(chosen, count)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    rank = np.arange(int(count.sum())) - np.repeat(first, count)
    piece = np.repeat(length / count, count)
    return edge_of.astype(np.int64), (rank + 0.5) * piece, piece


def positions_xy(network: CompiledNetwork, edges: IntArray, offsets: FloatArray) -> FloatArray:
    """Network coordinates of positions, shape ``(n, 2)``, along the edge shapes."""
    return np.array(
        [point_on_edge(network, int(e), float(s)) for e, s in zip(edges, offsets, strict=True)],
        dtype=np.float64,
    ).reshape(-1, 2)


def _positions(edges: IntArray, offsets: FloatArray) -> list[NetPosition]:
    return [NetPosition(int(e), float(s)) for e, s in zip(edges, offsets, strict=True)]
