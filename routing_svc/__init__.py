"""routing_svc: keeps a vehicle fleet where it is needed.

Stochastic-approximation deployment of service vehicles on road networks
(Le Ny & Pappas, "Adaptive Robot Deployment Algorithms").
"""

from routing_svc.paths import use_numba_cache

use_numba_cache()

__version__ = "0.1.0"
