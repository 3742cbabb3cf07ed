"""routing_svc: keeps a vehicle fleet where it is needed.

Stochastic-approximation deployment of service vehicles on road networks
(Le Ny & Pappas, "Adaptive Robot Deployment Algorithms").
"""

__version__ = "0.1.0"
