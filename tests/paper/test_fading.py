"""The relay chain: every link ends above the SNR threshold by bending through the good region."""

from __future__ import annotations

import numpy as np

from routing_svc.paper.fading import ChainProblem, deploy, make_radio_map, run
from routing_svc.sa.estimators import SpsaGains


def test_the_map_is_poor_below_and_good_above() -> None:
    radio = make_radio_map(np.random.default_rng(0))
    low = radio.shadow(np.array([[5.0, 0.5], [4.0, 1.0]]))
    high = radio.shadow(np.array([[5.0, 6.0], [4.0, 7.0]]))
    assert np.all(low < -12.0) and np.all(high > -6.0)


def test_every_link_ends_above_the_threshold() -> None:
    problem = ChainProblem()
    rng = np.random.default_rng(11)
    radio = make_radio_map(rng)
    straight = radio.mean_snr(problem.nodes(problem.straight_line()))
    assert straight.min() < problem.threshold - 2.0  # the straight chain fails
    gains = SpsaGains(a=0.4, c=0.3, stability=50.0)
    path = deploy(problem, radio, gains=gains, periods=1500, rng=rng)
    final = radio.mean_snr(problem.nodes(path[-1]))
    assert np.all(final > problem.threshold + 1.0), final
    assert path[-1][:, 1].max() > 2.0  # the chain bends upward
    assert np.all(path >= 0.0) and np.all(path[..., 0] <= radio.width)


def test_measured_snr_is_the_local_mean_plus_rayleigh_fading() -> None:
    problem = ChainProblem()
    radio = make_radio_map(np.random.default_rng(1))
    nodes = problem.nodes(problem.straight_line())
    rng = np.random.default_rng(2)
    samples = np.array([radio.measure_snr(nodes, rng) for _ in range(3000)])
    fading = samples - radio.mean_snr(nodes)
    # 10 log10(Exp(1)): mean -10 euler_gamma / ln 10 = -2.51 dB, std 5.57 dB
    assert np.allclose(fading.mean(axis=0), -2.507, atol=0.4)
    assert np.allclose(fading.std(axis=0), 5.57, atol=0.4)


def test_the_experiment_reports_all_links_above_threshold() -> None:
    result = run(seeds=1, quick=True, seed=0)
    assert result.summary["all_links_above_threshold_fraction"] == 1.0
    assert result.summary["final_min_snr_worst_db"] > result.summary["threshold_db"]
    assert result.summary["straight_chain_min_snr_median_db"] < result.summary["threshold_db"]
