"""Request streams: Poisson times, hotspot phases, local ride destinations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from routing_svc.demand import uniform_by_length
from routing_svc.errors import InvalidInput
from routing_svc.network import load_network
from routing_svc.sim.requests import Destinations, Phase, person_requests, poisson_times


def test_poisson_times_have_the_requested_rate() -> None:
    times = poisson_times(np.random.default_rng(0), rate_per_hour=360.0, start=0.0, end=36000.0)
    assert abs(len(times) - 3600) < 4 * 60  # 4 standard deviations
    assert times == sorted(times) and times[0] > 0.0 and times[-1] < 36000.0
    with pytest.raises(InvalidInput):
        poisson_times(np.random.default_rng(0), rate_per_hour=0.0, start=0.0, end=1.0)


def test_person_requests_follow_the_phase_in_force(grid_net: Path) -> None:
    network = load_network(grid_net)
    uniform = uniform_by_length(network)
    left = [p for p in uniform.positions if network.edge_ids[p.edge].startswith("A")]
    right = [p for p in uniform.positions if network.edge_ids[p.edge].startswith("F")]
    phases = [
        Phase(0.0, type(uniform).from_masses("left", left, np.ones(len(left)))),
        Phase(500.0, type(uniform).from_masses("right", right, np.ones(len(right)))),
    ]
    destinations = Destinations(network, uniform, radius=500.0)
    requests = person_requests(
        network, phases, destinations, rng=np.random.default_rng(1),
        rate_per_hour=360.0, start=0.0, end=1000.0,
    )  # fmt: skip
    assert len(requests) > 40
    for r in requests:
        assert r.edge.startswith("A" if r.time < 500.0 else "F")
        assert r.to_edge != r.edge
    again = person_requests(
        network, phases, destinations, rng=np.random.default_rng(1),
        rate_per_hour=360.0, start=0.0, end=1000.0,
    )  # fmt: skip
    assert again == requests


def test_ride_destinations_stay_within_the_radius(grid_net: Path) -> None:
    network = load_network(grid_net)
    destinations = Destinations(network, uniform_by_length(network), radius=250.0)
    rng = np.random.default_rng(2)
    origin = network.edge_index["C2C3"]
    # each edge's place is the mean of its shape points
    xy = np.array(
        [
            network.shape_xy[network.shape_offsets[e] : network.shape_offsets[e + 1]].mean(axis=0)
            for e in range(network.n_edges)
        ]
    )
    for _ in range(50):
        to = destinations.draw(rng, origin)
        assert to.edge != origin
        assert np.hypot(*(xy[to.edge] - xy[origin])) <= 250.0
