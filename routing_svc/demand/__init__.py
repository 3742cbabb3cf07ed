"""Demand distributions: finite sets of weighted atoms.

Expected costs over a :class:`DemandDistribution` are exact finite sums, so the
optimum of the routing/coverage objectives (``routing_svc.optimum``) and the
value reached by stochastic approximation can be compared without sampling
noise.

::

    DemandDistribution(name, positions, weights)     distribution.py
    uniform_by_length / hotspot_mixture /
    from_weights_file / from_buildings_file /
    from_edge_weights (road network)                  network.py, weights_file.py, buildings.py
    parse_demand_spec -> DemandRecipe,
    network_demand (the one --demand parser)          spec.py, profile.py
    uniform_rectangle / gaussian_mixture (plane)      plane.py
"""

from routing_svc.demand.distribution import DemandDistribution
from routing_svc.demand.network import (
    DEFAULT_SPACING,
    edge_pieces,
    from_buildings_file,
    from_edge_weights,
    from_weights_file,
    hotspot_mixture,
    positions_xy,
    uniform_by_length,
)
from routing_svc.demand.plane import gaussian_mixture, mixture_density, uniform_rectangle
from routing_svc.demand.spec import DemandRecipe, network_demand, parse_demand_spec

__all__ = [
    "DEFAULT_SPACING",
    "DemandDistribution",
    "DemandRecipe",
    "edge_pieces",
    "from_buildings_file",
    "from_edge_weights",
    "from_weights_file",
    "gaussian_mixture",
    "hotspot_mixture",
    "mixture_density",
    "network_demand",
    "parse_demand_spec",
    "positions_xy",
    "uniform_by_length",
    "uniform_rectangle",
]
