"""The combined search of dispatch and learning on a road network, against brute force."""

from __future__ import annotations

import math

import numpy as np

from routing_svc.network import RoadSpace, load_network
from routing_svc.sa import Requirement
from routing_svc.types import NetPosition
from tests.helpers import DRT


def test_one_road_search_gives_both_answers_like_brute_force() -> None:
    """The combined search (references and current positions, the mover among the
    learning groups) against one full scipy Dijkstra per vehicle."""
    net = load_network(DRT)
    space = RoadSpace(net)
    rng = np.random.default_rng(4)

    def spot() -> NetPosition:
        e = int(rng.integers(0, net.n_edges))
        return NetPosition(e, float(rng.uniform(0.0, net.length[e])))

    n = 8
    for _ in range(40):
        refs = [spot() for _ in range(n)]
        now = [spot() for _ in range(n)]
        available = rng.random(n) < 0.6
        available[0] = True
        senders = np.flatnonzero(available)
        target = spot()
        candidates = refs + [now[i] for i in senders]
        groups = np.concatenate(
            (np.zeros(n, dtype=np.int64), np.ones(senders.size, dtype=np.int64))
        )
        requirement = Requirement(groups, np.array([1, 1]), mover_groups=1)
        found = space.assign(target, candidates, np.ones(len(candidates)), requirement)
        to_refs = space.cost_matrix(refs, [target])[:, 0]
        to_now = space.cost_matrix([now[i] for i in senders], [target])[:, 0]
        assert found.mover == found.served_by[0] == int(np.argmin(to_refs))
        assert math.isclose(found.completion_time, float(to_refs.min()), rel_tol=1e-9)
        assert found.served_by[1] - n == int(np.argmin(to_now))
        assert math.isclose(found.times[1], float(to_now.min()), rel_tol=1e-9)
