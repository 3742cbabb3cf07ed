"""The optimum over stands: the p-median of a demand with sites restricted to stands.

.. math:: \\min_{S} \\sum_j w_j \\min_{i \\in S} d(s_i, z_j)^q

over multisets ``S`` of ``p`` stands with each stand at most its capacity times
(objective (11) of Le Ny & Pappas with the sites restricted). As
:mod:`routing_svc.sa.stands` argues, it opens ``min(p, n_stands)`` distinct
stands, solved by :func:`~routing_svc.optimum.pmedian.solve_pmedian` on the
cost matrix from the stands to the demand's atoms (an answer its exact method could
not prove optimal in time then goes through the variable neighbourhood search), and
parks the other vehicles
where capacity is free (:func:`~routing_svc.sa.stands.capacitated_sites`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.optimum.evaluate import CostModel
from routing_svc.optimum.pmedian import Method, PMedianSolution, objective, solve_pmedian
from routing_svc.optimum.solve import DemandOptimum, P
from routing_svc.sa.interchange import neighbourhood_search
from routing_svc.sa.stands import StandSet, capacitated_sites
from routing_svc.types import FloatArray, IntArray

MILP_MAX_CELLS = 1_000_000
"""``method="auto"`` solves the optimum over stands exactly (MILP, then polished) up to
this many (stand, demand atom) pairs, and by the heuristic beyond."""


@dataclass(frozen=True, slots=True)
class StandOptimum(DemandOptimum[P]):
    """A :class:`DemandOptimum` over stands; :attr:`positions` has one stand per vehicle
    (repeated where a stand holds several), :attr:`slots` their rows."""

    slots: IntArray


def solve_stands(
    space: CostModel[P],
    demand: DemandDistribution[P],
    p: int,
    stands: StandSet[P],
    *,
    power: float = 1.0,
    method: Method = "auto",
    time_limit: float = 60.0,
) -> StandOptimum[P]:
    """The p-median (``power = 1``) or p-power-median of ``demand`` over ``stands``
    (``method="auto"``: exact up to :data:`MILP_MAX_CELLS` stand-atom pairs).

    Raises
    ------
    InvalidInput
        More vehicles than the stands hold, or what :func:`solve_demand` rejects.
    """
    stands.check_fleet(p)
    sites = list(stands.positions)
    if method == "auto" and len(sites) * len(demand) > MILP_MAX_CELLS:
        method = "heuristic"
    matrix = space.cost_matrix(sites, list(demand.positions)) ** power
    weights = np.asarray(demand.weights, dtype=np.float64)
    solutions: list[PMedianSolution] = []

    def solve(k: int) -> IntArray:
        solutions.append(
            polished(
                solve_pmedian(matrix, weights, k, method=method, time_limit=time_limit),
                matrix,
                weights,
            )
        )
        return np.array(solutions[0].sites, dtype=np.int64)

    slots = capacitated_sites(matrix, weights, stands.capacities, p, solve)
    return StandOptimum([sites[i] for i in slots.tolist()], sites, matrix, solutions[0], slots)


def polished(solution: PMedianSolution, matrix: FloatArray, weights: FloatArray) -> PMedianSolution:
    """An unproven solution after the variable neighbourhood search
    (:func:`~routing_svc.sa.interchange.neighbourhood_search`), kept if it is better."""
    if solution.proven_optimal:
        return solution
    sites = neighbourhood_search(matrix, weights, np.array(solution.sites, dtype=np.int64))
    value = objective(matrix, weights, sites)
    if not value < solution.objective:
        return solution
    return replace(solution, sites=tuple(sorted(int(i) for i in sites)), objective=value)
