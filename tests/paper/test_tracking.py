"""Tracking: an asymptotically constant step follows a moving optimum, a decreasing one lags."""

from __future__ import annotations

import numpy as np

from routing_svc.paper.tracking import follow_hotspot, follow_source


def test_a_floored_spsa_gain_tracks_a_moving_source() -> None:
    errors = {
        rule: np.mean(
            [
                follow_source(rule, periods=1500, radius=2.5, rng=np.random.default_rng(s))[-400:]
                for s in range(3)
            ]
        )
        for rule in ("decreasing", "floor", "constant")
    }
    assert errors["floor"] < 0.4 and errors["constant"] < 0.4
    assert errors["decreasing"] > 2.0 * errors["floor"]


def test_a_floored_fleet_step_tracks_a_moving_hotspot() -> None:
    lags = {}
    for rule in ("decreasing", "floor"):
        _, lag = follow_hotspot(
            rule, targets=6000, turns=2.0, radius=2.5, rng=np.random.default_rng(4)
        )
        lags[rule] = lag[-25:].mean()
    assert lags["floor"] < 0.4
    assert lags["decreasing"] > 2.0 * lags["floor"]
