"""The one pipeline "candidate sites -> cost matrix -> p-median" of a demand distribution.

The optimum that every comparison in the project is judged against (the
service's reference optimum and its gap, the co-simulation's ``optimum``
policy, ``routing-svc optimum`` and ``simulate``, the learning benchmark) is
the p-median (or, with ``power = q``, the p-power-median) of a demand
distribution ``(z_j, w_j)``:

.. math:: \\min_{|S| = p} \\sum_j w_j \\min_{i \\in S} d(s_i, z_j)^q,

over candidate sites ``S``, with ``d`` the directed cost from a site to an atom
(eq. (10) of Le Ny & Pappas for ``q = 1``, eq. (9) for ``q = 2``). The steps:

1. candidate sites: on a road network the demand atoms plus the end of every
   edge (:func:`~routing_svc.optimum.candidates.candidate_sites`), at most
   :data:`MAX_SITES` of them, evenly subsampled; or sites the caller gives
   (the plane, a prior sample);
2. the cost matrix ``d(s_i, z_j)^q`` from the space;
3. optionally only the first of each group of identical rows
   (:func:`~routing_svc.optimum.candidates.distinct_rows`, same optimum);
4. :func:`~routing_svc.optimum.pmedian.solve_pmedian`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.errors import InvalidInput
from routing_svc.network import RoadSpace
from routing_svc.optimum.candidates import candidate_sites, distinct_rows
from routing_svc.optimum.evaluate import CostModel
from routing_svc.optimum.pmedian import Method, PMedianSolution, solve_pmedian
from routing_svc.types import FloatArray, NetPosition, PlanePosition

P = TypeVar("P", NetPosition, PlanePosition)

MAX_SITES = 1500
"""Candidate sites kept on a road network (subsampled deterministically beyond);
``solve_pmedian`` is exact up to ``MILP_MAX_SITES`` and heuristic above."""

MATRIX_BYTES = 2 * 2**30
"""The largest site-by-atom cost matrix solved (the heuristics hold its transpose too)."""


def sites_that_fit(atoms: int) -> int:
    """The most candidate sites whose cost matrix to ``atoms`` demand atoms fits in
    :data:`MATRIX_BYTES`."""
    return max(1, MATRIX_BYTES // (8 * max(atoms, 1)))


@dataclass(frozen=True, slots=True)
class DemandOptimum(Generic[P]):
    """The best ``p`` sites found for a demand distribution.

    Attributes
    ----------
    positions : list of positions
        The open sites, in the order of ``solution.sites`` (ascending rows).
    sites : list of positions
        The sites offered to the solver: the rows of ``matrix``.
    matrix : FloatArray
        ``d(sites[i], z_j) ** power``, shape ``(len(sites), n_atoms)``.
    solution : PMedianSolution
        The solver's answer (``sites`` index ``matrix`` rows; method, proof, bound, time).
    """

    positions: list[P]
    sites: list[P]
    matrix: FloatArray
    solution: PMedianSolution

    @property
    def objective(self) -> float:
        """``sum_j w_j min_{i in S} d(s_i, z_j)^q`` of the chosen sites."""
        return self.solution.objective


def solve_demand(
    space: CostModel[P],
    demand: DemandDistribution[P],
    p: int,
    *,
    sites: Sequence[P] | None = None,
    max_sites: int | None = MAX_SITES,
    power: float = 1.0,
    distinct: bool = False,
    method: Method = "auto",
    time_limit: float = 60.0,
) -> DemandOptimum[P]:
    """The p-median (``power = 1``) or p-power-median of ``demand``.

    Parameters
    ----------
    space : CostModel
        Gives the directed costs from sites to atoms (a ``RoadSpace`` when
        ``sites`` is omitted).
    demand : DemandDistribution
        The atoms ``z_j`` and weights ``w_j``.
    p : int
        Number of sites to open (vehicles).
    sites : sequence of positions, optional
        The candidate sites; default: ``candidate_sites(space.network, demand,
        max_sites=max_sites)``.
    max_sites : int or None
        Limit of the default candidate sites (``None``: every one); never more than
        :func:`sites_that_fit` the demand.
    power : float
        Exponent ``q`` of the service cost ``d ** q``.
    distinct : bool
        Offer only the first of each group of sites with identical cost rows.
    method, time_limit
        Passed to :func:`~routing_svc.optimum.pmedian.solve_pmedian`.

    Returns
    -------
    DemandOptimum

    Raises
    ------
    InvalidInput
        More vehicles than (distinct) candidate sites, given ``sites`` whose cost matrix
        exceeds :data:`MATRIX_BYTES`, or anything
        :func:`candidate_sites` or :func:`solve_pmedian` rejects.
    TypeError
        ``sites`` omitted for a space that is not a road network.
    """
    atoms = len(demand.positions)
    fit = sites_that_fit(atoms)
    offered: list[P] = (
        list(sites)
        if sites is not None
        else _network_sites(space, demand, fit if max_sites is None else min(max_sites, fit))
    )
    if len(offered) > fit:
        raise InvalidInput(
            f"the cost matrix of {len(offered)} sites x {atoms} demand atoms would take "
            f"{8 * len(offered) * atoms / 2**30:.1f} GiB, over the {MATRIX_BYTES / 2**30:g} GiB "
            f"solved: offer at most {fit} sites"
        )
    if not distinct:
        _check_fleet(p, len(offered), "candidate sites")
    matrix = space.cost_matrix(offered, list(demand.positions))
    if power != 1.0:  # ``d ** 1`` is ``d``: no second matrix of a large network's size
        matrix = matrix**power
    if distinct:
        rows = distinct_rows(matrix)
        _check_fleet(p, int(rows.size), "distinct candidate sites")
        if rows.size < len(offered):
            offered = [offered[int(i)] for i in rows]
            matrix = matrix[rows]
    solution = solve_pmedian(
        matrix, np.asarray(demand.weights), p, method=method, time_limit=time_limit
    )
    positions = [offered[i] for i in solution.sites]
    return DemandOptimum(positions, offered, matrix, solution)


def _network_sites(
    space: object, demand: DemandDistribution[Any], max_sites: int | None
) -> list[Any]:
    """The default candidate sites: demand atoms and edge ends of the space's network."""
    if not isinstance(space, RoadSpace):
        raise TypeError("candidate sites are drawn from a road network: pass `sites`")
    return candidate_sites(space.network, demand, max_sites=max_sites)


def _check_fleet(p: int, available: int, what: str) -> None:
    if isinstance(p, int) and p > available:
        raise InvalidInput(f"a fleet of {p} vehicles exceeds the {available} {what}")
