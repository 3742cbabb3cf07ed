"""Demand distributions on the Euclidean plane (the paper's setting).

Both constructors put atoms at the centres of a regular grid of cells over a
rectangle and give each atom the mass of its cell (the density at the cell
centre times the cell area, which is the midpoint rule). The finer the grid,
the closer the discrete measure is to the continuous one; every expectation
over it is an exact finite sum.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from routing_svc.demand.distribution import DemandDistribution
from routing_svc.errors import InvalidInput
from routing_svc.types import FloatArray, PlanePosition

Bounds = tuple[float, float, float, float]


def uniform_rectangle(bounds: Bounds, *, cells: int = 40) -> DemandDistribution[PlanePosition]:
    """Uniform demand on the rectangle ``bounds = (xmin, ymin, xmax, ymax)``.

    Parameters
    ----------
    bounds : tuple of float
        ``(xmin, ymin, xmax, ymax)`` with ``xmin < xmax`` and ``ymin < ymax``.
    cells : int
        Grid cells per side; ``cells**2`` atoms of equal weight.

    Returns
    -------
    DemandDistribution
        Atoms at the cell centres, each of weight ``1 / cells**2``.
    """
    xy = grid_centres(bounds, cells=cells)
    masses = np.ones(len(xy), dtype=np.float64)
    return DemandDistribution.from_masses(f"uniform_rectangle:{cells}x{cells}", xy, masses)


def gaussian_mixture(
    bounds: Bounds,
    *,
    centres: Sequence[tuple[float, float]],
    spread: float,
    weights: Sequence[float] | None = None,
    cells: int = 40,
) -> DemandDistribution[PlanePosition]:
    """A Gaussian mixture restricted to a rectangle and discretised on a grid.

    Parameters
    ----------
    bounds : tuple of float
        ``(xmin, ymin, xmax, ymax)``.
    centres : sequence of (x, y)
        Mixture component means.
    spread : float
        Standard deviation (isotropic, shared by all components), ``> 0``.
    weights : sequence of float, optional
        Component weights (non-negative, positive sum); equal if omitted.
    cells : int
        Grid cells per side.

    Returns
    -------
    DemandDistribution
        Atoms at the cell centres weighted by the mixture density, truncated
        to the rectangle and renormalised.
    """
    xy = grid_centres(bounds, cells=cells)
    points = np.array(xy, dtype=np.float64)
    masses = mixture_density(points, centres=centres, spread=spread, weights=weights)
    name = f"gaussian_mixture:{len(centres)}"
    return DemandDistribution.from_masses(name, xy, masses)


def grid_centres(bounds: Bounds, *, cells: int) -> list[PlanePosition]:
    """Centres of a ``cells x cells`` grid over ``bounds``, row by row (y outer)."""
    xmin, ymin, xmax, ymax = (float(b) for b in bounds)
    if not all(math.isfinite(b) for b in (xmin, ymin, xmax, ymax)):
        raise InvalidInput(f"rectangle bounds must be finite, got {bounds!r}")
    if not (xmin < xmax and ymin < ymax):
        raise InvalidInput(f"rectangle bounds need xmin < xmax and ymin < ymax, got {bounds!r}")
    if isinstance(cells, bool) or not isinstance(cells, int) or cells < 1:
        raise InvalidInput(f"cells must be an integer >= 1, got {cells!r}")
    xs = xmin + (np.arange(cells) + 0.5) * ((xmax - xmin) / cells)
    ys = ymin + (np.arange(cells) + 0.5) * ((ymax - ymin) / cells)
    return [PlanePosition(float(x), float(y)) for y in ys for x in xs]


def mixture_density(
    points: FloatArray,
    *,
    centres: Sequence[tuple[float, float]],
    spread: float,
    weights: Sequence[float] | None = None,
) -> FloatArray:
    """Density of an isotropic Gaussian mixture at ``points`` (shape ``(n, 2)``).

    ``f(z) = sum_k a_k / (2 pi s^2) exp(-|z - c_k|^2 / (2 s^2))`` with the
    component weights ``a_k`` normalised to sum to one.

    Raises
    ------
    InvalidInput
        No centres, non-finite centres, ``spread <= 0``, or bad weights.
    """
    c = np.asarray(centres, dtype=np.float64)
    if c.ndim != 2 or c.shape[0] == 0 or c.shape[1] != 2 or not np.all(np.isfinite(c)):
        raise InvalidInput("hotspot centres must be a non-empty list of finite (x, y) pairs")
    if not math.isfinite(spread) or spread <= 0.0:
        raise InvalidInput(f"spread must be a finite number > 0, got {spread!r}")
    a = np.ones(len(c)) if weights is None else np.asarray(weights, dtype=np.float64)
    if a.shape != (len(c),) or not np.all(np.isfinite(a)) or np.any(a < 0) or a.sum() <= 0:
        raise InvalidInput(
            f"hotspot weights must be {len(c)} finite numbers >= 0 with a positive sum"
        )
    a = a / a.sum()
    sq = ((points[:, None, :] - c[None, :, :]) ** 2).sum(axis=2)
    dens: FloatArray = (np.exp(-sq / (2.0 * spread**2)) * a).sum(axis=1)
    return dens / (2.0 * math.pi * spread**2)
