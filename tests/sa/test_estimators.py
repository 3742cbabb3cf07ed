"""Gradient estimators: unbiasedness on a quadratic, exact formation weights."""

from __future__ import annotations

import math
from functools import partial

import numpy as np
import pytest

from routing_svc.errors import InvalidInput
from routing_svc.sa.estimators import (
    SpsaGains,
    descend,
    formation_gradient,
    formation_weights,
    kiefer_wolfowitz_gradient,
    rademacher,
    regular_polygon,
    spsa_from_values,
    spsa_gradient,
)
from routing_svc.types import FloatArray

HESSIAN = np.array([[3.0, 1.0, 0.0], [1.0, 2.0, -0.5], [0.0, -0.5, 1.0]])
LINEAR = np.array([0.5, -1.0, 2.0])
NOISE = 0.3


def quadratic(points: FloatArray) -> FloatArray:
    """``J(x) = x^T H x / 2 + b^T x``, gradient ``H x + b``."""
    return np.asarray(
        0.5 * np.einsum("ij,jk,ik->i", points, HESSIAN, points) + points @ LINEAR, dtype=np.float64
    )


def noisy_quadratic(points: FloatArray, rng: np.random.Generator) -> FloatArray:
    return quadratic(points) + rng.normal(0.0, NOISE, size=len(points))


def exact_gradient(x: FloatArray) -> FloatArray:
    return np.asarray(HESSIAN @ x + LINEAR, dtype=np.float64)


def _assert_unbiased(samples: FloatArray, truth: FloatArray) -> None:
    mean = samples.mean(axis=0)
    stderr = samples.std(axis=0, ddof=1) / math.sqrt(len(samples))
    assert np.all(np.abs(mean - truth) < 4.0 * stderr + 1e-12), (mean, truth, stderr)


def test_kiefer_wolfowitz_is_unbiased_on_a_quadratic() -> None:
    rng = np.random.default_rng(1)
    x = np.array([0.7, -1.2, 0.4])
    samples = np.array(
        [kiefer_wolfowitz_gradient(noisy_quadratic, x, c=0.2, rng=rng) for _ in range(4000)]
    )
    _assert_unbiased(samples, exact_gradient(x))
    # the noise of a central difference is NOISE / (sqrt(2) c) per coordinate
    assert np.allclose(samples.std(axis=0), NOISE / (math.sqrt(2) * 0.2), rtol=0.05)


def test_kiefer_wolfowitz_is_exact_without_noise() -> None:
    x = np.array([0.3, 0.1, -2.0])
    g = kiefer_wolfowitz_gradient(
        lambda p, _rng: quadratic(p), x, c=0.5, rng=np.random.default_rng(0)
    )
    np.testing.assert_allclose(g, exact_gradient(x), atol=1e-12)


def test_spsa_is_unbiased_on_a_quadratic() -> None:
    rng = np.random.default_rng(2)
    x = np.array([1.0, 0.5, -0.5])
    samples = np.array([spsa_gradient(noisy_quadratic, x, c=0.1, rng=rng) for _ in range(20000)])
    _assert_unbiased(samples, exact_gradient(x))


def test_spsa_uses_two_measurements_along_one_perturbation() -> None:
    calls: list[FloatArray] = []

    def recording(points: FloatArray, rng: np.random.Generator) -> FloatArray:
        calls.append(points.copy())
        return quadratic(points)

    x = np.array([0.2, 0.4, 0.6])
    g = spsa_gradient(recording, x, c=0.25, rng=np.random.default_rng(3))
    assert len(calls) == 1 and calls[0].shape == (2, 3)
    delta = (calls[0][0] - x) / 0.25
    np.testing.assert_allclose(np.abs(delta), 1.0)
    np.testing.assert_allclose(calls[0][1], x - 0.25 * delta)
    # without noise the estimate is the directional derivative along delta, times 1/delta
    np.testing.assert_allclose(g, (exact_gradient(x) @ delta) / delta, atol=1e-12)


def test_spsa_from_values_is_componentwise() -> None:
    delta = np.array([1.0, -1.0, 1.0])
    g = spsa_from_values(np.array([3.0, 1.0, 2.0]), np.array([1.0, 2.0, 2.0]), delta, c=0.5)
    np.testing.assert_allclose(g, [2.0, 1.0, 0.0])


def test_rademacher_entries_are_balanced_signs() -> None:
    draws = rademacher(100_000, np.random.default_rng(4))
    assert set(np.unique(draws)) == {-1.0, 1.0}
    assert abs(draws.mean()) < 4.0 / math.sqrt(len(draws))


def test_triangle_weights_are_the_papers() -> None:
    delta = 0.8
    weights = formation_weights(regular_polygon(3, radius=delta))
    s3 = math.sqrt(3.0)
    np.testing.assert_allclose(weights[0], np.array([2 / 3, -1 / 3, -1 / 3]) / delta, atol=1e-12)
    np.testing.assert_allclose(weights[1], np.array([0.0, s3 / 3, -s3 / 3]) / delta, atol=1e-12)


@pytest.mark.parametrize("count", [3, 4, 5, 7])
def test_formation_weights_are_exact_on_affine_fields(count: int) -> None:
    rng = np.random.default_rng(count)
    offsets = regular_polygon(count, radius=0.6, angle=0.4) + rng.normal(0.0, 0.1, (count, 2))
    weights = formation_weights(offsets)
    slope, level = np.array([1.7, -0.4]), 3.0
    centre = np.array([2.0, -1.0])
    g = formation_gradient(
        lambda p, _rng: p @ slope + level,
        centre,
        offsets=offsets,
        weights=weights,
        rng=rng,
    )
    np.testing.assert_allclose(g, slope, atol=1e-10)
    np.testing.assert_allclose(weights.sum(axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(weights @ offsets, np.eye(2), atol=1e-12)


def test_more_robots_lower_the_noise_of_the_formation_estimate() -> None:
    three = formation_weights(regular_polygon(3, radius=1.0))
    six = formation_weights(regular_polygon(6, radius=1.0))
    # under i.i.d. noise the variance of g_i is NOISE^2 * sum_j W[i, j]^2
    assert np.all((six**2).sum(axis=1) < (three**2).sum(axis=1))


def test_formation_gradient_is_unbiased_on_a_quadratic_for_a_symmetric_formation() -> None:
    offsets = regular_polygon(4, radius=0.5)
    weights = formation_weights(offsets)
    hessian = np.array([[2.0, 0.5], [0.5, 1.0]])

    def field(points: FloatArray, rng: np.random.Generator) -> FloatArray:
        values = 0.5 * np.einsum("ij,jk,ik->i", points, hessian, points)
        return np.asarray(values + rng.normal(0.0, NOISE, len(points)), dtype=np.float64)

    centre = np.array([1.0, -0.5])
    rng = np.random.default_rng(5)
    samples = np.array(
        [
            formation_gradient(field, centre, offsets=offsets, weights=weights, rng=rng)
            for _ in range(4000)
        ]
    )
    _assert_unbiased(samples, hessian @ centre)


def test_degenerate_formations_are_refused() -> None:
    with pytest.raises(InvalidInput):
        formation_weights(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]))
    with pytest.raises(InvalidInput):
        formation_weights(np.array([[1.0, 0.0], [0.0, 1.0]]))
    with pytest.raises(InvalidInput):
        formation_weights(np.array([[np.nan, 0.0], [1.0, 0.0], [0.0, 1.0]]))


def test_gains_follow_the_power_laws() -> None:
    gains = SpsaGains(a=2.0, c=0.5, alpha=0.602, gamma=0.101, stability=10.0)
    assert gains.step(0) == pytest.approx(2.0 / 11.0**0.602)
    assert gains.perturbation(9) == pytest.approx(0.5 / 10.0**0.101)
    assert gains.robbins_monro()
    floored = SpsaGains(a=1.0, c=0.1, alpha=1.0, floor=0.05)
    assert floored.step(10_000) == 0.05 and not floored.robbins_monro()
    with pytest.raises(InvalidInput):
        SpsaGains(a=1.0, c=0.1, alpha=1.5)
    with pytest.raises(InvalidInput):
        SpsaGains(a=-1.0, c=0.1)


def test_spsa_descent_finds_the_minimum_of_a_noisy_quadratic() -> None:
    rng = np.random.default_rng(6)
    minimiser = np.linalg.solve(HESSIAN, -LINEAR)
    path = descend(
        partial(spsa_gradient, noisy_quadratic),
        np.zeros(3),
        gains=SpsaGains(a=0.2, c=0.2, stability=20.0),
        iterations=3000,
        rng=rng,
    )
    assert path.shape == (3001, 3)
    # the start is 1.96 away; the seeded run ends 0.12 away
    assert np.linalg.norm(path[0] - minimiser) > 1.9
    assert np.linalg.norm(path[-1] - minimiser) < 0.25


def test_descent_respects_the_box() -> None:
    rng = np.random.default_rng(7)
    path = descend(
        partial(kiefer_wolfowitz_gradient, noisy_quadratic),
        np.zeros(3),
        gains=SpsaGains(a=0.2, c=0.2),
        iterations=200,
        rng=rng,
        lower=np.full(3, -0.25),
        upper=np.full(3, 0.25),
    )
    assert np.all(path >= -0.25) and np.all(path <= 0.25)


def test_same_seed_same_trajectory() -> None:
    def run(seed: int) -> FloatArray:
        return descend(
            partial(spsa_gradient, noisy_quadratic),
            np.ones(3),
            gains=SpsaGains(a=0.1, c=0.1),
            iterations=50,
            rng=np.random.default_rng(seed),
        )

    np.testing.assert_array_equal(run(8), run(8))
    assert not np.array_equal(run(8), run(9))
