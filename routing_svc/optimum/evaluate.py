"""Exact expected service cost of a fleet configuration.

For vehicle positions ``p_i`` with speed factors ``v_i``, a discrete demand
distribution ``(z_j, w_j)`` and the service cost ``c(T) = T**q`` (``q = 1``:
routing objective, eq. (10) of Le Ny & Pappas; ``q = 2``: coverage, eq. (9)),
the expected cost of the homogeneous requirement "any one vehicle" is

.. math:: J(p) = \\sum_j w_j \\min_i \\left( d(p_i, z_j) / v_i \\right)^q,

where ``d`` is the directed cost *from* the vehicle *to* the target. It is
computed here exactly from one cost matrix, with no sampling.

The cost model is anything with ``cost_matrix(sources, targets)``: the road
network space (``routing_svc.network.RoadSpace``), the Euclidean plane, or a
plain matrix in tests.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol, TypeVar

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.errors import InvalidInput, Unreachable
from routing_svc.types import FloatArray, NetPosition, PlanePosition

P = TypeVar("P", NetPosition, PlanePosition)
Q = TypeVar("Q")


class CostModel(Protocol[Q]):
    """Directed travel costs between positions."""

    def cost_matrix(self, sources: list[Q], targets: list[Q]) -> FloatArray:
        """Costs ``d(sources[i], targets[j])``, shape ``(len(sources), len(targets))``.

        Declared with ``list`` parameters so that implementations accepting
        either ``list`` or any ``Sequence`` conform.
        """
        ...


def expected_cost(
    model: CostModel[P],
    positions: Sequence[P],
    speeds: Sequence[float] | FloatArray,
    demand: DemandDistribution[P],
    *,
    power: float = 1.0,
) -> float:
    """Exact expected service cost ``sum_j w_j min_i (d(p_i, z_j) / v_i)**power``.

    Parameters
    ----------
    model : CostModel
        Gives the directed cost matrix from vehicles to demand atoms.
    positions : sequence of positions
        Vehicle reference positions ``p_i``.
    speeds : array_like
        Speed factors ``v_i > 0``, one per vehicle.
    demand : DemandDistribution
        The atoms ``z_j`` and weights ``w_j``.
    power : float
        Exponent ``q > 0`` of the service cost ``c(T) = T**q``.

    Returns
    -------
    float
        The expected cost (in cost units, e.g. metres or seconds, to the power ``q``).

    Raises
    ------
    InvalidInput
        No vehicles, bad speeds or power, or a cost matrix of the wrong shape.
    Unreachable
        A demand atom that no vehicle can reach.
    """
    if not positions:
        raise InvalidInput("expected cost needs at least one vehicle")
    v = _validated_speeds(speeds, len(positions))
    costs = np.asarray(model.cost_matrix(list(positions), list(demand.positions)), dtype=np.float64)
    if costs.shape != (len(positions), len(demand.positions)):
        raise InvalidInput(
            f"cost model returned shape {costs.shape}, "
            f"expected {(len(positions), len(demand.positions))}"
        )
    return expected_cost_from_matrix(costs / v[:, None], demand.weights, power=power)


def expected_cost_from_matrix(
    times: FloatArray, weights: FloatArray, *, power: float = 1.0
) -> float:
    """``sum_j w_j min_i times[i, j]**power`` for a ready vehicle-by-atom matrix.

    Raises
    ------
    InvalidInput
        Shape mismatch, negative or NaN entries, or a bad power.
    Unreachable
        A column (demand atom) with no finite entry.
    """
    if not math.isfinite(power) or power <= 0.0:
        raise InvalidInput(f"power must be a finite number > 0, got {power!r}")
    if times.ndim != 2 or times.shape[0] == 0 or times.shape[1] != weights.shape[0]:
        raise InvalidInput(f"cost matrix of shape {times.shape} does not match the demand")
    if np.any(np.isnan(times)) or np.any(times < 0.0):
        raise InvalidInput("costs must be non-negative numbers")
    best = times.min(axis=0)
    unreachable = np.flatnonzero(~np.isfinite(best))
    if unreachable.size:
        raise Unreachable(
            f"demand atom {int(unreachable[0])} cannot be reached from any vehicle "
            f"({unreachable.size} such atoms)"
        )
    return math.fsum((weights * best**power).tolist())


def gap(value: float, optimum: float) -> float | None:
    """Relative gap ``(value - optimum) / optimum`` of a cost to the optimal cost.

    Parameters
    ----------
    value : float
        Expected cost of a configuration (e.g. after stochastic approximation).
    optimum : float
        The optimal (or best known) expected cost.

    Returns
    -------
    float or None
        ``0.0`` when both are zero; ``None`` when ``optimum == 0 < value`` (no
        finite relative gap exists: a demand of no more places than vehicles);
        otherwise the relative excess over the optimum (negative if ``value``
        beats a non-optimal reference).

    Raises
    ------
    InvalidInput
        Non-finite or negative inputs.
    """
    if not (math.isfinite(value) and math.isfinite(optimum)) or value < 0 or optimum < 0:
        raise InvalidInput(f"gap needs finite costs >= 0, got {value!r} and {optimum!r}")
    if optimum == 0.0:
        return 0.0 if value == 0.0 else None
    return (value - optimum) / optimum


def _validated_speeds(speeds: Sequence[float] | FloatArray, n: int) -> FloatArray:
    """Speeds as a float array of length ``n``, all finite and ``> 0``."""
    v = np.asarray(speeds, dtype=np.float64)
    if v.shape != (n,):
        raise InvalidInput(f"expected {n} speeds, got shape {v.shape}")
    if not np.all(np.isfinite(v)) or np.any(v <= 0.0):
        raise InvalidInput("speeds must be finite and > 0")
    return v
