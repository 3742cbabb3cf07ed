"""``simulate --start prior:N`` starts where a fleet created at the optimum of that sample
would: the p-median over the sample *and* the edge ends (Hakimi's candidates)."""

from __future__ import annotations

import numpy as np
import pytest

from routing_svc.offline_run import network_scenario, starting_positions
from routing_svc.types import NetPosition


def test_a_prior_start_may_wait_at_the_junction_before_its_targets() -> None:
    scenario = network_scenario(
        "drt", demand="hotspots:3", vehicles=1, cost="length", rng=np.random.default_rng(0)
    )
    space = scenario.space
    net = space.network
    # an edge c whose end turns into three edges that do not lead back where c came from
    for c in range(net.n_edges):
        out = net.fwd_indices[net.fwd_indptr[c] : net.fwd_indptr[c + 1]].tolist()
        ahead = [e for e in out if net.edge_to[e] != net.edge_from[c] and net.length[e] > 2.0]
        if len(ahead) >= 3:
            break
    targets = [NetPosition(e, 1.0) for e in ahead[:3]]
    costs = space.cost_matrix([NetPosition(c, float(net.length[c])), *targets], targets)
    assert costs[0].tolist() == pytest.approx([1.0, 1.0, 1.0])  # the junction: 1 m to each
    # a target's own place serves the others at 2 m at best (back to the junction, on)
    assert all(costs[1 + i].sum() >= 4.0 - 1e-9 for i in range(3))
    (start,), used = starting_positions(scenario, targets * 2, start="prior:6", power=1.0)
    assert used == 6
    # the best single place serves all three at 1 m: the end of an edge into that junction
    assert start.offset == float(net.length[start.edge]) and start not in targets
    assert space.cost_matrix([start], targets)[0].tolist() == pytest.approx([1.0, 1.0, 1.0])
