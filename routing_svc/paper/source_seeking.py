"""Source seeking: a formation against a single SPSA robot (sections II-A, IV-A).

A scalar field ``J`` (a concentration, a signal loss) has its minimum at the
source. Robots only measure ``J`` with noise and descend a gradient
estimate. Three strategies get the same field, the same start and the same
gains ``a_k = a / (k + 1 + A)**alpha``:

- *formation*: three robots on an equilateral triangle of radius ``delta``
  around the centre, one measurement each per period; the centre moves by
  eq. (5) with the triangle weights of :func:`formation_weights`;
- *shrinking*: the same triangle with radius ``c_k`` (our addition: the
  rigid triangle is not symmetric under ``x -> -x``, so on a curved field its
  estimate has a bias of order ``delta`` and the formation settles
  ``O(delta)`` away from the source);
- *spsa*: one robot, two measurements per period at ``x +- c_k Delta_k``,
  eq. (18);
- *kw*: one robot, four measurements per period, eq. (17), as a reference.

The paper conjectures that a single SPSA robot does about as well as the
formation. The field (our choice; the paper gives none) is the anisotropic
"pseudo-Huber" bowl

``J(x) = sqrt(1 + (x - s)^T H (x - s)) - 1``,

quadratic near the source ``s`` and conical far from it (bounded gradient,
like the decay of a plume), with ``H`` of condition number 4 rotated 30
degrees. The noise is Gaussian with a standard deviation that grows with the
distance to the source, ``sigma(x) = sigma_0 (1 + |x - s| / 2)``: the
measurements are worst where the robots start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from routing_svc.paper.result import ExperimentResult, quantile_band, seed_generators
from routing_svc.sa.estimators import (
    FormationEstimate,
    GradientEstimate,
    Measurement,
    SpsaGains,
    descend,
    kiefer_wolfowitz_gradient,
    regular_polygon,
    spsa_gradient,
)
from routing_svc.types import FloatArray

STRATEGIES = ("formation", "shrinking", "spsa", "kw")
MEASUREMENTS_PER_PERIOD = {"formation": 3, "shrinking": 3, "spsa": 2, "kw": 4}


@dataclass(frozen=True, slots=True)
class SourceField:
    """``J(x) = sqrt(1 + (x - s)^T H (x - s)) - 1`` measured with position-dependent noise.

    Attributes
    ----------
    source : tuple[float, float]
        ``s``, the minimiser.
    hessian : tuple[tuple[float, float], tuple[float, float]]
        ``H`` (symmetric positive definite): the curvature at the source.
    noise : float
        ``sigma_0``; the noise at ``x`` has standard deviation
        ``sigma_0 (1 + |x - s| / 2)``.
    """

    source: tuple[float, float] = (7.0, 6.0)
    hessian: tuple[tuple[float, float], tuple[float, float]] = ((0.8125, 0.3248), (0.3248, 0.4375))
    noise: float = 0.1

    def value(self, points: FloatArray) -> FloatArray:
        """The noiseless field at each row of ``points``."""
        offset = np.asarray(points, dtype=np.float64) - np.asarray(self.source)
        quad = np.einsum("ij,jk,ik->i", offset, np.asarray(self.hessian), offset)
        return np.asarray(np.sqrt(1.0 + quad) - 1.0, dtype=np.float64)

    def measure(self, points: FloatArray, rng: np.random.Generator) -> FloatArray:
        """Noisy measurements: a :data:`Measurement`."""
        distance = np.linalg.norm(np.asarray(points) - np.asarray(self.source), axis=1)
        sigma = self.noise * (1.0 + distance / 2.0)
        noisy = self.value(points) + sigma * rng.standard_normal(len(distance))
        return np.asarray(noisy, dtype=np.float64)


def estimator(strategy: str, measure: Measurement, *, radius: float) -> GradientEstimate:
    """The gradient estimate of a strategy (one of :data:`STRATEGIES`)."""
    if strategy == "formation":
        return FormationEstimate.rigid(measure, regular_polygon(3, radius=radius))
    if strategy == "shrinking":
        return FormationEstimate.shrinking_with_c(measure, regular_polygon(3, radius=1.0))
    if strategy == "spsa":
        return partial(spsa_gradient, measure)
    if strategy == "kw":
        return partial(kiefer_wolfowitz_gradient, measure)
    raise ValueError(f"unknown strategy {strategy!r}")


def seek(
    strategy: str,
    *,
    field: SourceField,
    start: FloatArray,
    gains: SpsaGains,
    periods: int,
    radius: float,
    rng: np.random.Generator,
) -> FloatArray:
    """One run of one strategy: the centre's path, shape ``(periods + 1, 2)``.

    For the formation ``radius`` is the triangle's fixed radius and ``c_k`` is
    not used; for SPSA and KW the perturbation is ``c_k`` from ``gains``.
    """
    estimate = estimator(strategy, field.measure, radius=radius)
    return descend(estimate, start, gains=gains, iterations=periods, rng=rng)


def run(*, seeds: int, quick: bool, seed: int = 0) -> ExperimentResult:
    """Compare the three strategies over ``seeds`` seeded runs.

    Every seed uses one generator per strategy, derived from the same
    ``SeedSequence`` child, so the strategies are independent of each other
    and each run is reproducible on its own.
    """
    field = SourceField()
    start = np.array([1.0, 1.0])
    periods = 150 if quick else 400
    radius = 0.4
    gains = SpsaGains(a=1.5, c=radius, alpha=0.602, gamma=0.101, stability=10.0)
    found_radius = 0.5
    source = np.asarray(field.source)
    distances: dict[str, FloatArray] = {}
    finals: dict[str, FloatArray] = {}
    for strategy in STRATEGIES:
        runs = []
        for rng in seed_generators(seed, seeds):
            path = seek(
                strategy,
                field=field,
                start=start,
                gains=gains,
                periods=periods,
                radius=radius,
                rng=rng,
            )
            runs.append(np.linalg.norm(path - source, axis=1))
        distances[strategy] = np.array(runs)
        finals[strategy] = distances[strategy][:, -1]
    summary: dict[str, object] = {
        "start_distance": float(np.linalg.norm(start - source)),
        "found_radius": found_radius,
    }
    for strategy in STRATEGIES:
        final = finals[strategy]
        within = distances[strategy] <= found_radius
        summary[strategy] = {
            "measurements_per_period": MEASUREMENTS_PER_PERIOD[strategy],
            "final_distance_median": float(np.median(final)),
            "final_distance_q90": float(np.quantile(final, 0.9)),
            "found_fraction": float(np.mean(final <= found_radius)),
            "median_periods_to_radius": float(np.median(_first_stay(within))),
        }
    summary["spsa_over_formation_final_median"] = float(
        np.median(finals["spsa"]) / np.median(finals["formation"])
    )
    series = {
        "period": np.arange(periods + 1),
        **{strategy: quantile_band(distances[strategy]) for strategy in STRATEGIES},
        "finals": finals,
    }
    return ExperimentResult(
        name="source-seeking",
        title="Source seeking: a triangle formation (eq. 5) vs one SPSA robot (eq. 18)",
        params={
            "seeds": seeds,
            "seed": seed,
            "periods": periods,
            "source": field.source,
            "hessian": field.hessian,
            "noise_sigma0": field.noise,
            "start": start,
            "formation_radius": radius,
            "gains": {
                "a": gains.a,
                "c": gains.c,
                "alpha": gains.alpha,
                "gamma": gains.gamma,
                "A": gains.stability,
            },
        },
        summary=summary,
        series=series,
    )


def _first_stay(within: np.ndarray[tuple[int, int], np.dtype[np.bool_]]) -> FloatArray:
    """For each run, the first period from which the path stays within the radius (inf: never)."""
    stays = np.flip(np.logical_and.accumulate(np.flip(within, axis=1), axis=1), axis=1)
    first = np.where(stays.any(axis=1), np.argmax(stays, axis=1), math.inf)
    return np.asarray(first, dtype=np.float64)
