"""Demand in the plane for the paper's fleet experiments, and feeding it to a fleet.

Targets are drawn from a mixture of isotropic Gaussian hotspots (optionally
each hotspot with a required vehicle-type multiset, for the heterogeneous
fleet of section IV-C). :func:`feed` gives a stream of targets to a
:class:`~routing_svc.sa.fleet.Fleet` (the update rules are the core's, not
re-implemented here) and records the positions at chosen checkpoints.
:func:`expected_cost` evaluates ``E[min_i |p_i - z|**q]`` on a sample.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from routing_svc.sa import EuclideanPlane, Fleet, FleetConfig, Vehicle
from routing_svc.types import FloatArray, PlanePosition


@dataclass(frozen=True, slots=True)
class Hotspot:
    """One mixture component: where, how spread, how likely, which vehicles it needs."""

    centre: tuple[float, float]
    spread: float
    weight: float
    requires: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Mixture:
    """A mixture of Gaussian hotspots."""

    hotspots: tuple[Hotspot, ...]

    def probabilities(self) -> FloatArray:
        """The normalised component weights."""
        weights = np.array([h.weight for h in self.hotspots], dtype=np.float64)
        return np.asarray(weights / weights.sum(), dtype=np.float64)

    def sample(self, rng: np.random.Generator, n: int) -> tuple[FloatArray, FloatArray]:
        """``n`` targets ``(n, 2)`` and the index of the hotspot of each."""
        component = rng.choice(len(self.hotspots), size=n, p=self.probabilities())
        centres = np.array([h.centre for h in self.hotspots], dtype=np.float64)
        spreads = np.array([h.spread for h in self.hotspots], dtype=np.float64)
        points = centres[component] + spreads[component, None] * rng.standard_normal((n, 2))
        return np.asarray(points, dtype=np.float64), np.asarray(component, dtype=np.float64)


def plane_fleet(
    positions: FloatArray,
    *,
    config: FleetConfig,
    side: float,
    types: Sequence[str] | None = None,
) -> Fleet[PlanePosition]:
    """A fleet on the Euclidean plane with vehicles ``v00, v01, ...`` at ``positions``."""
    kinds = list(types) if types is not None else ["default"] * len(positions)
    vehicles = [
        (Vehicle(f"v{i:02d}", kind), PlanePosition(float(x), float(y)))
        for i, ((x, y), kind) in enumerate(zip(positions, kinds, strict=True))
    ]
    return Fleet.create(EuclideanPlane(side=side), vehicles, config)


def fleet_positions(fleet: Fleet[PlanePosition]) -> FloatArray:
    """The fleet's positions as an ``(n, 2)`` array in vehicle order."""
    return np.asarray(fleet.state.positions, dtype=np.float64).reshape(-1, 2)


def feed(
    fleet: Fleet[PlanePosition],
    targets: FloatArray,
    *,
    checkpoints: Sequence[int],
    requires: Sequence[tuple[str, ...]] | None = None,
) -> list[FloatArray]:
    """Give ``targets`` to ``fleet.observe`` in order; positions after each checkpoint.

    ``checkpoints`` are numbers of targets seen (0 = the start); ``requires``
    gives the required types of each target (none: any one vehicle).
    """
    marks = sorted(set(checkpoints))
    snapshots: list[FloatArray] = []
    seen = 0
    for mark in marks:
        while seen < mark:
            needs = requires[seen] if requires is not None else None
            fleet.observe(PlanePosition(*targets[seen]), needs or None)
            seen += 1
        snapshots.append(fleet_positions(fleet))
    return snapshots


def distances(points: FloatArray, sites: FloatArray) -> FloatArray:
    """Euclidean distances, shape ``(len(points), len(sites))``."""
    diff = points[:, None, :] - sites[None, :, :]
    return np.asarray(np.hypot(diff[..., 0], diff[..., 1]), dtype=np.float64)


def expected_cost(
    points: FloatArray, sites: FloatArray, *, power: float, weights: FloatArray | None = None
) -> float:
    """``sum_j w_j min_i |p_i - z_j|**q`` (mean over ``points`` when unweighted).

    ``q = 2`` is the coverage objective (9), ``q = 1`` the routing objective (10).
    """
    nearest = distances(points, sites).min(axis=1) ** power
    if weights is None:
        return float(nearest.mean())
    return float(np.sum(weights * nearest) / np.sum(weights))
