"""Gradient estimators from noisy measurements (section IV of the paper).

When a robot can only *measure* a field ``J`` (a concentration, a signal
strength, a link SNR) and never its gradient, stochastic approximation
estimates the gradient from differences of noisy measurements and descends
along the estimate:

- :func:`kiefer_wolfowitz_gradient`: eq. (17), one central difference per
  coordinate (``2 d`` measurements per period);
- :func:`spsa_gradient`: Spall's simultaneous perturbation, eq. (18), two
  measurements per period whatever the dimension, with Rademacher
  perturbations;
- :func:`formation_weights` / :func:`formation_gradient`: the gradient at the
  centre of a rigid formation as a weighted sum of one measurement per robot,
  eq. (5), with the weights found by the method of undetermined coefficients;
- :func:`descend`: the iteration ``x_{k+1} = x_k - a_k g_k`` with the gains
  ``a_k = a / (k + 1 + A)**alpha`` and ``c_k = c / (k + 1)**gamma`` of
  :class:`SpsaGains`.

Everything here is pure: randomness comes from a ``numpy.random.Generator``
passed in, and a *measurement* is a callable ``measure(points, rng)`` that
returns one noisy value per row of ``points`` (an ``(m, d)`` array).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from routing_svc.errors import InvalidInput
from routing_svc.types import FloatArray

Measurement = Callable[[FloatArray, np.random.Generator], FloatArray]
"""``measure(points, rng) -> values``: one noisy measurement per row of ``points``."""


class GradientEstimate(Protocol):
    """``estimate(x, c=c_k, rng=rng) -> g_k``: a gradient estimate at ``x``.

    :func:`spsa_gradient` and :func:`kiefer_wolfowitz_gradient` with the
    measurement bound (``functools.partial``) are gradient estimates, and so is
    :class:`FormationEstimate`.
    """

    def __call__(self, x: FloatArray, *, c: float, rng: np.random.Generator) -> FloatArray: ...


def _point(x: FloatArray) -> FloatArray:
    point = np.asarray(x, dtype=np.float64)
    if point.ndim != 1 or point.size == 0 or not np.all(np.isfinite(point)):
        raise InvalidInput("a point must be a non-empty finite 1-d array")
    return point


def _perturbation(c: float) -> float:
    if not math.isfinite(c) or c <= 0.0:
        raise InvalidInput(f"the perturbation c must be a finite number > 0, got {c!r}")
    return float(c)


def rademacher(dim: int, rng: np.random.Generator) -> FloatArray:
    """``dim`` i.i.d. Rademacher entries (``+1`` or ``-1`` with probability 1/2).

    These satisfy Spall's condition that ``E[1 / Delta_i]`` is bounded, which
    a Gaussian or uniform perturbation does not.
    """
    return rng.integers(0, 2, size=dim).astype(np.float64) * 2.0 - 1.0


def kiefer_wolfowitz_gradient(
    measure: Measurement, x: FloatArray, *, c: float, rng: np.random.Generator
) -> FloatArray:
    """Kiefer-Wolfowitz finite-difference gradient, eq. (17).

    ``g_i = (J(x + c e_i) - J(x - c e_i)) / (2 c)`` for each coordinate ``i``,
    from ``2 d`` noisy measurements. For a quadratic ``J`` and zero-mean noise
    the estimate is unbiased; in general its bias is ``O(c**2)``.

    Parameters
    ----------
    measure : Measurement
        Noisy measurements of ``J``.
    x : FloatArray
        The point, shape ``(d,)``.
    c : float
        The perturbation ``c_k > 0``.
    rng : numpy.random.Generator
        Source of the measurement noise.
    """
    point = _point(x)
    step = _perturbation(c)
    eye = np.eye(point.size) * step
    values = measure(np.vstack([point + eye, point - eye]), rng)
    d = point.size
    return np.asarray((values[:d] - values[d:]) / (2.0 * step), dtype=np.float64)


def spsa_from_values(
    plus: FloatArray | float, minus: FloatArray | float, delta: FloatArray, *, c: float
) -> FloatArray:
    """The arithmetic of eq. (18): ``(y+ - y-) / (2 c) * Delta**-1`` componentwise.

    ``plus`` and ``minus`` are measurements at ``x + c Delta`` and
    ``x - c Delta``; they may be arrays broadcasting against ``delta`` (a
    chain of robots, each with its own local measurements and perturbation).
    """
    step = _perturbation(c)
    difference = np.asarray(plus, dtype=np.float64) - np.asarray(minus, dtype=np.float64)
    return np.asarray(difference / (2.0 * step) / delta, dtype=np.float64)


def spsa_gradient(
    measure: Measurement, x: FloatArray, *, c: float, rng: np.random.Generator
) -> FloatArray:
    """Spall's simultaneous-perturbation gradient, eq. (18).

    ``g = (J(x + c Delta) - J(x - c Delta)) / (2 c) * Delta**-1`` with
    ``Delta`` a vector of i.i.d. Rademacher entries: two measurements per
    period in any dimension. For a quadratic ``J`` the estimate is unbiased
    (the cross terms ``Delta_j / Delta_i`` have mean zero); in general its
    bias is ``O(c**2)``.

    Parameters
    ----------
    measure : Measurement
        Noisy measurements of ``J``.
    x : FloatArray
        The point, shape ``(d,)``.
    c : float
        The perturbation ``c_k > 0``.
    rng : numpy.random.Generator
        Source of the perturbation and the measurement noise.
    """
    point = _point(x)
    step = _perturbation(c)
    delta = rademacher(point.size, rng)
    values = measure(np.vstack([point + step * delta, point - step * delta]), rng)
    return spsa_from_values(values[0], values[1], delta, c=step)


def formation_weights(offsets: FloatArray) -> FloatArray:
    """Finite-difference weights of a rigid formation (eq. (5)).

    Robot ``j`` sits at ``x + o_j``. The estimate ``g_i = sum_j W[i, j] J(x + o_j)``
    must be exact for every affine ``J``. By the method of undetermined
    coefficients (Taylor expansion to first order) this is

    ``sum_j W[i, j] = 0`` and ``sum_j W[i, j] o_j = e_i`` for every ``i``,

    ``d + 1`` linear conditions per coordinate. With ``d + 1`` robots the
    weights are unique; with more, the minimum-norm solution is returned, which
    has the least variance under i.i.d. measurement noise. For the equilateral
    triangle of radius ``delta`` with a robot on the x axis the weights are
    ``(2/3, -1/3, -1/3) / delta`` in x and ``(0, sqrt(3)/3, -sqrt(3)/3) / delta``
    in y, the paper's.

    Parameters
    ----------
    offsets : FloatArray
        Robot offsets from the centre, shape ``(m, d)``.

    Returns
    -------
    FloatArray
        ``W``, shape ``(d, m)``.

    Raises
    ------
    InvalidInput
        When the offsets are not finite or do not span the space affinely
        (fewer than ``d + 1`` robots, or robots on a line in the plane).
    """
    points = np.asarray(offsets, dtype=np.float64)
    if points.ndim != 2 or not np.all(np.isfinite(points)):
        raise InvalidInput("formation offsets must be a finite (m, d) array")
    m, d = points.shape
    conditions = np.vstack([np.ones((1, m)), points.T])
    if m < d + 1 or np.linalg.matrix_rank(conditions) < d + 1:
        raise InvalidInput(
            f"a formation of {m} robots in {d} dimensions must span the space affinely"
        )
    right = np.vstack([np.zeros((1, d)), np.eye(d)])
    weights = np.linalg.pinv(conditions) @ right
    return np.asarray(weights.T, dtype=np.float64)


def regular_polygon(count: int, *, radius: float, angle: float = 0.0) -> FloatArray:
    """Offsets of ``count`` robots evenly spaced on a circle of ``radius``.

    The first robot is at polar angle ``angle`` (0: on the positive x axis);
    ``count = 3`` is the paper's equilateral triangle.
    """
    if count < 3:
        raise InvalidInput(f"a planar formation needs at least 3 robots, got {count}")
    _perturbation(radius)
    angles = angle + 2.0 * np.pi * np.arange(count) / count
    return np.column_stack([np.cos(angles), np.sin(angles)]) * radius


def formation_gradient(
    measure: Measurement,
    centre: FloatArray,
    *,
    offsets: FloatArray,
    weights: FloatArray,
    rng: np.random.Generator,
) -> FloatArray:
    """Gradient at the formation's centre from one measurement per robot, eq. (5).

    ``g = W @ [J(x + o_1), ..., J(x + o_m)]`` with ``W`` from
    :func:`formation_weights`.
    """
    point = _point(centre)
    values = measure(point + np.asarray(offsets, dtype=np.float64), rng)
    return np.asarray(weights @ values, dtype=np.float64)


@dataclass(frozen=True, slots=True)
class FormationEstimate:
    """A formation as a :class:`GradientEstimate` (eq. (5)).

    A *rigid* formation keeps its size (``c_k`` is ignored); its estimate has
    a bias of order ``radius`` wherever the field is not affine over the
    formation (none for a quadratic and a formation symmetric under ``-1``,
    but the triangle is not). A *shrinking* formation scales its offsets by
    ``c_k`` (and its weights by ``1 / c_k``), so the bias vanishes as
    ``c_k -> 0``, like the perturbation of SPSA.

    Attributes
    ----------
    measure : Measurement
        Noisy measurements of the field.
    offsets : FloatArray
        Offsets ``(m, d)`` (for a shrinking formation: at unit scale).
    weights : FloatArray
        Their weights ``(d, m)`` from :func:`formation_weights`.
    shrinking : bool
        Whether the offsets scale with ``c_k``.
    """

    measure: Measurement
    offsets: FloatArray
    weights: FloatArray
    shrinking: bool = False

    @classmethod
    def rigid(cls, measure: Measurement, offsets: FloatArray) -> FormationEstimate:
        """The formation at fixed ``offsets``."""
        points = np.asarray(offsets, dtype=np.float64)
        return cls(measure, points, formation_weights(points))

    @classmethod
    def shrinking_with_c(cls, measure: Measurement, unit_offsets: FloatArray) -> FormationEstimate:
        """The formation at ``c_k * unit_offsets`` in period ``k``."""
        points = np.asarray(unit_offsets, dtype=np.float64)
        return cls(measure, points, formation_weights(points), shrinking=True)

    def __call__(self, x: FloatArray, *, c: float, rng: np.random.Generator) -> FloatArray:
        if not self.shrinking:
            return formation_gradient(
                self.measure, x, offsets=self.offsets, weights=self.weights, rng=rng
            )
        scale = _perturbation(c)
        return formation_gradient(
            self.measure, x, offsets=self.offsets * scale, weights=self.weights / scale, rng=rng
        )


@dataclass(frozen=True, slots=True)
class SpsaGains:
    """Gain sequences ``a_k = a / (k + 1 + A)**alpha`` and ``c_k = c / (k + 1)**gamma``.

    Convergence of eqs. (17)-(18) needs ``a_k -> 0``, ``c_k -> 0``,
    ``sum a_k = inf`` and ``sum (a_k / c_k)**2 < inf``, that is
    ``0 < alpha <= 1``, ``gamma > 0`` and ``alpha - gamma > 1/2``; Spall's
    practical choice is ``alpha = 0.602``, ``gamma = 0.101``. ``alpha = 0``
    gives a constant step (tracking, section III-D); ``floor`` keeps
    ``a_k >= floor`` (asymptotically constant).

    Attributes
    ----------
    a, c : float
        Scales of the step and of the perturbation.
    alpha, gamma : float
        Decay powers.
    stability : float
        ``A``, delays the decay of the step so that early steps are not huge.
    floor : float
        Lower bound of ``a_k`` (0: none).
    """

    a: float
    c: float
    alpha: float = 0.602
    gamma: float = 0.101
    stability: float = 0.0
    floor: float = 0.0

    def __post_init__(self) -> None:
        for name in ("a", "c"):
            _perturbation(getattr(self, name))
        for name in ("alpha", "gamma", "stability", "floor"):
            value = getattr(self, name)
            if not math.isfinite(value) or value < 0.0:
                raise InvalidInput(f"{name} must be a finite number >= 0, got {value!r}")
        if self.alpha > 1.0:
            raise InvalidInput(f"alpha must be <= 1 (sum a_k = inf), got {self.alpha!r}")

    def step(self, k: int) -> float:
        """``a_k``."""
        return max(float(self.a / (k + 1.0 + self.stability) ** self.alpha), self.floor)

    def perturbation(self, k: int) -> float:
        """``c_k``."""
        return float(self.c / (k + 1.0) ** self.gamma)

    def robbins_monro(self) -> bool:
        """Whether the conditions for convergence to a minimum hold."""
        return self.floor == 0.0 and self.alpha > 0.0 and self.alpha - self.gamma > 0.5


def descend(
    estimate: GradientEstimate,
    x0: FloatArray,
    *,
    gains: SpsaGains,
    iterations: int,
    rng: np.random.Generator,
    lower: FloatArray | None = None,
    upper: FloatArray | None = None,
) -> FloatArray:
    """Run ``x_{k+1} = x_k - a_k g_k`` (eq. (5) with eq. (17) or (18)).

    Parameters
    ----------
    estimate : GradientEstimate
        ``estimate(x, c=c_k, rng=rng)``, e.g.
        ``functools.partial(spsa_gradient, measure)``.
    x0 : FloatArray
        Start, shape ``(d,)``.
    gains : SpsaGains
        ``a_k`` and ``c_k``.
    iterations : int
        Number of periods.
    rng : numpy.random.Generator
        Source of all randomness.
    lower, upper : FloatArray, optional
        A box the iterate is projected onto after each step.

    Returns
    -------
    FloatArray
        The trajectory, shape ``(iterations + 1, d)``, starting with ``x0``.
    """
    if iterations < 0:
        raise InvalidInput(f"iterations must be >= 0, got {iterations}")
    x = _point(x0).copy()
    path = np.empty((iterations + 1, x.size), dtype=np.float64)
    path[0] = x
    for k in range(iterations):
        x = x - gains.step(k) * estimate(x, c=gains.perturbation(k), rng=rng)
        if lower is not None or upper is not None:
            x = np.clip(x, lower, upper)
        path[k + 1] = x
    return path
