"""Heterogeneous routing: A and B vehicles pair up near (6, 6); the objective (11) falls."""

from __future__ import annotations

import numpy as np

from routing_svc.paper.heterogeneous import completion_time, demand, pairs_near, run


def test_a_and_b_pair_up_near_6_6_and_the_objective_falls() -> None:
    result = run(seeds=2, quick=True, seed=1)
    assert result.summary["seeds_with_a_pair_near_6_6"] == 2
    assert result.summary["pair_separation_median"] < 0.2
    assert result.summary["objective_final_median"] < 0.4 * result.summary["objective_start_median"]
    curve = np.asarray(result.series["objective"]["median"])
    assert curve[-1] < curve[len(curve) // 4] < curve[0]


def test_completion_time_is_the_last_arrival() -> None:
    mixture = demand(0.5)
    sites = np.array([[0.0, 0.0], [3.0, 0.0]])
    types = ["A", "B"]
    targets = np.array([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0]])
    kinds = np.array([0.0, 1.0, 2.0])  # a, b, ab
    # a: A arrives after 1; b: B after 2; ab: the later of both, 2
    assert completion_time(targets, kinds, mixture, sites, types) == (1.0 + 2.0 + 2.0) / 3


def test_pairs_are_mutually_nearest_and_close() -> None:
    sites = np.array([[6.0, 6.0], [2.0, 6.0], [6.1, 6.0], [6.0, 2.0]])
    types = ["A", "A", "B", "B"]
    pairs = pairs_near(sites, types, centre=(6.0, 6.0), radius=1.0, gap=0.5)
    assert [(a, b) for a, b, _ in pairs] == [(0, 2)]
    assert pairs_near(sites, types, centre=(2.0, 6.0), radius=1.0, gap=0.5) == []
