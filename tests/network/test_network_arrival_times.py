"""``RoadSpace.arrival_times``: the search with a time cutoff, against the full search."""

from __future__ import annotations

import numpy as np
import pytest

from routing_svc.network import RoadSpace
from routing_svc.sa.space import Requirement
from tests.network.conftest import NetCase


@pytest.mark.parametrize("either_way", [True, False])
def test_times_below_the_cutoff_match_the_full_search(case: NetCase, either_way: bool) -> None:
    space = RoadSpace(case.network, either_way=either_way)
    rng = np.random.default_rng(51)
    for _ in range(60):
        n = int(rng.integers(1, 40))
        positions = case.random_positions(rng, n)
        speeds = rng.uniform(0.5, 2.0, n)
        target = case.random_positions(rng, 1)[0]
        every = Requirement(np.arange(n, dtype=np.int64), np.ones(n, dtype=np.int64))
        full = space.assign(target, positions, speeds, every)
        exact = np.full(n, np.inf)
        exact[list(full.served_by)] = full.times
        cutoff = float(np.quantile(exact, rng.uniform(0.0, 1.0)))
        times = space.arrival_times(target, positions, speeds, cutoff)
        expected = np.where(exact < cutoff, exact, np.inf)
        np.testing.assert_array_equal(times, expected)
        assert np.array_equal(space.arrival_times(target, positions, speeds, np.inf), exact)
