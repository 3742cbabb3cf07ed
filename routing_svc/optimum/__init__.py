"""The exact expected cost of a configuration and the p-median optimum.

::

    expected_cost(model, positions, speeds, demand, power=q)  evaluate.py
    gap(value, optimum)                                       evaluate.py
    solve_pmedian(costs, weights, p, method="auto")           pmedian.py
        greedy, fast interchange, neighbourhood search        interchange.py
        Lagrangian bound and site reduction                   lagrangian.py
    candidate_sites(network, demand, max_sites=...)           candidates.py
    solve_demand(space, demand, p, sites=..., power=q)        solve.py
        candidate sites -> cost matrix -> solve_pmedian
    routing-svc optimum                                       command.py
"""

from routing_svc.optimum.candidates import candidate_sites, distinct_rows
from routing_svc.optimum.evaluate import CostModel, expected_cost, expected_cost_from_matrix, gap
from routing_svc.optimum.pmedian import PMedianSolution, objective, solve_pmedian
from routing_svc.optimum.solve import MAX_SITES, DemandOptimum, solve_demand

__all__ = [
    "MAX_SITES",
    "CostModel",
    "DemandOptimum",
    "PMedianSolution",
    "candidate_sites",
    "distinct_rows",
    "expected_cost",
    "expected_cost_from_matrix",
    "gap",
    "objective",
    "solve_demand",
    "solve_pmedian",
]
