"""A relay chain under random wireless fading (sections II-B, IV-B, Fig. 1).

Six robots relay between a base at the origin and a target beyond the base's
range. The SNR of a link is only known through noisy measurements, and the
radio map is unknown to the robots.

Radio model (the paper's structure, our numbers), in dB:

``SNR_ij = P0 - 10 n log10(d_ij) + (S(x_i) + S(x_j)) / 2 + F``

- path loss with exponent ``n`` (``P0`` at unit distance, distances floored
  at ``0.1``);
- shadowing ``S``: a fixed map, the mean of the values at both ends of the
  link. ``S`` is a smooth random field (Gaussian-filtered white noise of
  standard deviation ``shadow_sigma`` and correlation length
  ``correlation``) plus a poor block of ``-poor_level`` dB between base and
  target below ``y = clear_height``, fading out linearly upward (so the map is
  poor except in the upper part) and with soft edges at ``x = 2`` and
  ``x = width - 2`` (line of sight near base and target);
- fast fading ``F``: Rayleigh, ``F = 10 log10(E)`` with ``E ~ Exp(1)``, drawn
  anew for every measurement (mean -2.5 dB, standard deviation 5.6 dB).

The potential, eq. (6) of the paper with our choice of penalty, over the
links ``l = (i, j)`` of the chain base - 1 - ... - 6 - target, is

``U(x) = E[ sum_l kappa (SNR_th - SNR_l)_+**2 ] + (lambda / 2) sum_l |x_i - x_j|**2``:

a quadratic penalty on the SNR deficit of each link (in expectation over the
fading) and springs that keep the chain short and evenly spread. Robot ``i``
descends the part of ``U`` that depends on its own position (its two
links). Each period all robots perturb their positions by ``c_k Delta_i``
(Rademacher) and then by ``-c_k Delta_i``, every link is measured once in
each configuration, and robot ``i`` forms, from the measurements of its two
links only,

``g_i = (P_i(+) - P_i(-)) / (2 c_k) Delta_i**-1 + lambda (2 x_i - x_{i-1} - x_{i+1})``

where ``P_i`` is the penalty of its two links (SPSA, eq. (18), section IV-B);
the spring term is computed exactly because robots know their positions. The
neighbours' simultaneous perturbations are independent of ``Delta_i`` and
average out, as in SPSA. Positions are projected onto the environment box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter

from routing_svc.paper.result import ExperimentResult, quantile_band, seed_generators, thinned
from routing_svc.sa.estimators import SpsaGains, rademacher, spsa_from_values
from routing_svc.types import FloatArray


@dataclass(frozen=True, slots=True)
class RadioMap:
    """Path loss and a fixed shadowing map on ``[0, width] x [0, height]``.

    Attributes
    ----------
    shadowing : FloatArray
        ``S`` in dB on a regular grid, shape ``(ny, nx)``, row ``r`` at
        ``y = r * resolution``.
    resolution : float
        Grid spacing.
    p0, exponent : float
        ``P0`` (dB at unit distance) and the path-loss exponent ``n``.
    """

    shadowing: FloatArray
    resolution: float
    p0: float = 32.0
    exponent: float = 3.0

    @property
    def width(self) -> float:
        """The environment's extent in x."""
        return float((self.shadowing.shape[1] - 1) * self.resolution)

    @property
    def height(self) -> float:
        """The environment's extent in y."""
        return float((self.shadowing.shape[0] - 1) * self.resolution)

    def shadow(self, points: FloatArray) -> FloatArray:
        """``S`` at each row of ``points`` (bilinear interpolation)."""
        ny, nx = self.shadowing.shape
        gx = np.clip(points[..., 0] / self.resolution, 0.0, nx - 1.000001)
        gy = np.clip(points[..., 1] / self.resolution, 0.0, ny - 1.000001)
        ix, iy = gx.astype(np.int64), gy.astype(np.int64)
        fx, fy = gx - ix, gy - iy
        grid = self.shadowing
        low = grid[iy, ix] * (1 - fx) + grid[iy, ix + 1] * fx
        high = grid[iy + 1, ix] * (1 - fx) + grid[iy + 1, ix + 1] * fx
        return np.asarray(low * (1 - fy) + high * fy, dtype=np.float64)

    def mean_snr(self, nodes: FloatArray) -> FloatArray:
        """Local-mean SNR (no fast fading) of consecutive links of a chain ``(..., m, 2)``."""
        distance = np.linalg.norm(np.diff(nodes, axis=-2), axis=-1)
        shadow = self.shadow(nodes)
        loss = self.p0 - 10.0 * self.exponent * np.log10(np.maximum(distance, 0.1))
        return np.asarray(loss + 0.5 * (shadow[..., 1:] + shadow[..., :-1]), dtype=np.float64)

    def measure_snr(self, nodes: FloatArray, rng: np.random.Generator) -> FloatArray:
        """One measurement of every link: local mean plus Rayleigh fading."""
        mean = self.mean_snr(nodes)
        return mean + 10.0 * np.log10(rng.exponential(size=mean.shape))


def make_radio_map(
    rng: np.random.Generator,
    *,
    width: float = 10.0,
    height: float = 8.0,
    resolution: float = 0.1,
    poor_level: float = 22.0,
    clear_height: float = 4.0,
    shadow_sigma: float = 2.0,
    correlation: float = 0.8,
) -> RadioMap:
    """Draw the shadowing map described in the module docstring."""
    xs = np.arange(round(width / resolution) + 1) * resolution
    ys = np.arange(round(height / resolution) + 1) * resolution
    gx, gy = np.meshgrid(xs, ys)
    rising = np.clip((clear_height - gy) / clear_height, 0.0, 1.0)
    edge = 0.5

    def sigmoid(t: FloatArray) -> FloatArray:
        return np.asarray(1.0 / (1.0 + np.exp(-t)), dtype=np.float64)

    block = sigmoid((gx - 2.0) / edge) * sigmoid((width - 2.0 - gx) / edge)
    noise = gaussian_filter(rng.standard_normal(gx.shape), correlation / resolution)
    noise *= shadow_sigma / noise.std()
    return RadioMap(shadowing=noise - poor_level * rising * block, resolution=resolution)


@dataclass(frozen=True, slots=True)
class ChainProblem:
    """The chain's endpoints and the potential's constants (eq. (6))."""

    base: tuple[float, float] = (0.0, 0.0)
    target: tuple[float, float] = (10.0, 0.0)
    robots: int = 6
    threshold: float = 10.0
    kappa: float = 0.02
    spring: float = 0.02

    def nodes(self, positions: FloatArray) -> FloatArray:
        """Base, robots, target as one ``(..., robots + 2, 2)`` array."""
        shape = (*positions.shape[:-2], 1, 2)
        base = np.broadcast_to(np.asarray(self.base), shape)
        target = np.broadcast_to(np.asarray(self.target), shape)
        return np.concatenate([base, positions, target], axis=-2)

    def straight_line(self) -> FloatArray:
        """Robots evenly spaced on the segment from base to target."""
        t = np.arange(1, self.robots + 1) / (self.robots + 1)
        base, target = np.asarray(self.base), np.asarray(self.target)
        return np.asarray(base + t[:, None] * (target - base), dtype=np.float64)

    def penalty(self, snr: FloatArray) -> FloatArray:
        """``kappa (SNR_th - SNR)_+**2`` per link."""
        return np.asarray(self.kappa * np.maximum(self.threshold - snr, 0.0) ** 2)


def deploy(
    problem: ChainProblem,
    radio: RadioMap,
    *,
    gains: SpsaGains,
    periods: int,
    rng: np.random.Generator,
) -> FloatArray:
    """Minimise the potential (6) with the distributed SPSA estimate; return the path.

    Returns
    -------
    FloatArray
        Robot positions in every period, shape ``(periods + 1, robots, 2)``.
    """
    x = problem.straight_line()
    path = np.empty((periods + 1, *x.shape))
    path[0] = x
    lower, upper = np.zeros(2), np.array([radio.width, radio.height])
    for k in range(periods):
        c = gains.perturbation(k)
        delta = np.stack([rademacher(2, rng) for _ in range(problem.robots)])
        plus = problem.penalty(radio.measure_snr(problem.nodes(x + c * delta), rng))
        minus = problem.penalty(radio.measure_snr(problem.nodes(x - c * delta), rng))
        # robot i owns links i (to its predecessor) and i + 1 (to its successor)
        own_plus = (plus[:-1] + plus[1:])[:, None]
        own_minus = (minus[:-1] + minus[1:])[:, None]
        nodes = problem.nodes(x)
        springs = problem.spring * (2.0 * x - nodes[:-2] - nodes[2:])
        g = spsa_from_values(own_plus, own_minus, delta, c=c) + springs
        x = np.clip(x - gains.step(k) * g, lower, upper)
        path[k + 1] = x
    return path


def run(*, seeds: int, quick: bool, seed: int = 0) -> ExperimentResult:
    """Deploy the chain on ``seeds`` independently drawn radio maps."""
    problem = ChainProblem()
    periods = 1500 if quick else 4000
    gains = SpsaGains(a=0.4, c=0.3, alpha=0.602, gamma=0.101, stability=50.0)
    snapshot_periods = sorted({0, periods // 20, periods // 5, periods})
    min_snr, finals, paths, maps = [], [], [], []
    for rng in seed_generators(seed, seeds):
        radio = make_radio_map(rng)
        path = deploy(problem, radio, gains=gains, periods=periods, rng=rng)
        snr = radio.mean_snr(problem.nodes(path))
        min_snr.append(snr.min(axis=1))
        finals.append(snr[-1])
        paths.append(path[snapshot_periods])
        maps.append(radio)
    min_curve, final_snr = np.array(min_snr), np.array(finals)
    straight = [r.mean_snr(problem.nodes(problem.straight_line())).min() for r in maps]
    first = maps[0]
    keep = thinned(periods + 1)
    summary = {
        "threshold_db": problem.threshold,
        "straight_chain_min_snr_median_db": float(np.median(straight)),
        "final_min_snr_median_db": float(np.median(final_snr.min(axis=1))),
        "final_min_snr_worst_db": float(final_snr.min()),
        "all_links_above_threshold_fraction": float(
            np.mean(final_snr.min(axis=1) > problem.threshold)
        ),
        "final_max_height_median": float(np.median([p[-1, :, 1].max() for p in paths])),
    }
    return ExperimentResult(
        name="fading",
        title="Relay chain under fading: SPSA on the potential (6) with neighbour measurements",
        params={
            "seeds": seeds,
            "seed": seed,
            "periods": periods,
            "robots": problem.robots,
            "base": problem.base,
            "target": problem.target,
            "threshold_db": problem.threshold,
            "kappa": problem.kappa,
            "spring": problem.spring,
            "p0_db": first.p0,
            "path_loss_exponent": first.exponent,
            "gains": {"a": gains.a, "c": gains.c, "alpha": gains.alpha, "gamma": gains.gamma},
        },
        summary=summary,
        series={
            "period": keep,
            "min_link_snr": quantile_band(min_curve, keep=keep),
            "snapshot_periods": snapshot_periods,
            "snapshots": paths[0],
            "final_link_snr_seed0": final_snr[0],
            "shadowing_seed0": first.shadowing[::2, ::2],
            "extent": [0.0, first.width, 0.0, first.height],
        },
    )
