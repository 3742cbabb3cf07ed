"""Candidate sites for the network p-median.

Hakimi (1964) showed that an undirected network p-median with demand at the
vertices has an optimal solution located at vertices; with demand spread over
edges it suffices to add the demand points, so *demand points + vertices* is
a finite candidate set that contains an exact optimum.

In this project's directed edge model a position ``(e, s)`` reaches a target
``(e', s')`` at cost ``(len(e) - s) + D(e, e') + s'`` (times the edge's cost
rate), or ``s' - s`` when ``e = e'`` and ``s <= s'``. As ``s`` grows along
``e`` every such cost *decreases* linearly and jumps up just after passing a
target on ``e``, so the objective ``sum_j w_j min_i d(p_i, z_j)``, as a
function of one site's offset, is smallest at an atom of ``e`` or at the
*end* of ``e`` (offset ``len(e)``: at the junction, free to take any allowed
turn). On a two-way street ``RoadSpace`` by default lets a vehicle leave
either way (the cost is the smaller one from ``(e, s)`` and from its twin
``(r, len(r) (1 - s / len(e)))`` on the reverse edge ``r``). Between the
breakpoints (atoms of ``e``, points facing the atoms of ``r``, the two ends)
the objective is then a minimum of linear functions, hence concave, and again
smallest at a breakpoint; a point facing an atom of ``r`` is equivalent to
that atom, and the start of ``e`` to the end of ``r``. Either way, the demand
atoms plus the end of every edge contain an exact optimum. (The start of an
edge, offset 0, is never needed.)

Ends of edges that enter the same junction with the same allowed turns give
identical cost rows; :func:`distinct_rows` removes such duplicates after the
cost matrix is computed, without changing the optimum.
"""

from __future__ import annotations

import hashlib

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork
from routing_svc.types import FloatArray, IntArray, NetPosition


def candidate_sites(
    network: CompiledNetwork,
    demand: DemandDistribution[NetPosition],
    *,
    max_sites: int | None = None,
) -> list[NetPosition]:
    """Demand atoms followed by the end of every edge, without repeats.

    Parameters
    ----------
    network : CompiledNetwork
        The network the demand lives on.
    demand : DemandDistribution
        Atoms on ``network``.
    max_sites : int, optional
        If there are more candidates, keep ``max_sites`` of them, deterministically:
        every atom and, in the room left, edge ends evenly spaced in edge order
        when there are fewer atoms than ``max_sites`` (an atom is the one site
        that serves itself at no cost, so a demand of few places keeps them all);
        otherwise ``max_sites`` evenly spaced in the whole list. Edge indices
        follow a space-filling curve, so the kept ends spread over the map. The
        result is then a heuristic restriction: the optimum over it may be worse
        than the true optimum.

    Returns
    -------
    list of NetPosition
        The candidate sites.

    Raises
    ------
    InvalidInput
        ``max_sites < 1``, or atoms whose edge is not in ``network``.
    """
    if max_sites is not None and (isinstance(max_sites, bool) or max_sites < 1):
        raise InvalidInput(f"max_sites must be an integer >= 1, got {max_sites!r}")
    if any(not 0 <= p.edge < network.n_edges for p in demand.positions):
        raise InvalidInput("demand atoms refer to edges that are not in this network")
    atoms = list(dict.fromkeys(demand.positions))
    ends = [NetPosition(e, float(network.length[e])) for e in range(network.n_edges)]
    sites = list(dict.fromkeys([*atoms, *ends]))  # the atoms first, then the other ends
    if max_sites is None or len(sites) <= max_sites:
        return sites
    if len(atoms) < max_sites:
        return atoms + _evenly_spaced(sites[len(atoms) :], max_sites - len(atoms))
    return _evenly_spaced(sites, max_sites)


def _evenly_spaced(sites: list[NetPosition], count: int) -> list[NetPosition]:
    """``count`` of ``sites`` (``1 <= count <= len(sites)``) at evenly spaced places in the
    list, the first always among them."""
    keep = np.unique(np.linspace(0, len(sites) - 1, count).round().astype(np.int64))
    return [sites[int(i)] for i in keep]


def distinct_rows(costs: FloatArray) -> IntArray:
    """Indices of the first occurrence of every distinct row, ascending.

    Sites with identical cost rows are interchangeable in a p-median, so only
    one of each needs to be offered to the solver. Rows are grouped by a digest of
    their values and compared within a group, without a sorted copy of the matrix.
    """
    if costs.ndim != 2:
        raise InvalidInput(f"expected a 2-D cost matrix, got shape {costs.shape}")
    rows = np.ascontiguousarray(costs, dtype=np.float64)
    first: dict[bytes, list[int]] = {}  # a digest of a row's bits -> rows kept with it
    kept = []
    for i, row in enumerate(rows):
        bits = (row + 0.0).data  # -0.0 + 0.0 is 0.0: equal rows, equal bits
        alike = first.setdefault(hashlib.blake2b(bits, digest_size=16).digest(), [])
        if not any(np.array_equal(rows[j], row) for j in alike):
            alike.append(i)
            kept.append(i)
    return np.array(kept, dtype=np.int64)
