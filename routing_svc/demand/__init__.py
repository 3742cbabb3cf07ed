"""Demand distributions: finite sets of weighted atoms.

Expected costs over a :class:`DemandDistribution` are exact finite sums, so the
optimum of the routing/coverage objectives (``routing_svc.optimum``) and the
value reached by stochastic approximation can be compared without sampling
noise.

::

    DemandDistribution(name, positions, weights)     distribution.py
    uniform_by_length / hotspot_mixture /
    from_weights_file (road network)                  network.py, weights_file.py
    uniform_rectangle / gaussian_mixture (plane)      plane.py
"""

from routing_svc.demand.distribution import DemandDistribution
from routing_svc.demand.network import (
    DEFAULT_SPACING,
    edge_pieces,
    from_weights_file,
    hotspot_mixture,
    positions_xy,
    uniform_by_length,
)
from routing_svc.demand.plane import gaussian_mixture, mixture_density, uniform_rectangle

__all__ = [
    "DEFAULT_SPACING",
    "DemandDistribution",
    "edge_pieces",
    "from_weights_file",
    "gaussian_mixture",
    "hotspot_mixture",
    "mixture_density",
    "positions_xy",
    "uniform_by_length",
    "uniform_rectangle",
]
