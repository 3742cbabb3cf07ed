"""Posts: where the available vehicles wait while others are busy (move-up).

A fleet learns one reference per vehicle: where it waits when every vehicle is
free. A busy vehicle leaves its reference uncovered, and the closest free vehicle
of a target beside it comes from a neighbouring cell. The available vehicles
therefore hold *posts*, chosen again whenever availability changes (a compliance
table in the terms of emergency medical services, built from the learnt
references):

1. per vehicle type, with ``k`` of its ``n`` vehicles available, the ``k`` posts
   among the ``n`` references of the type that minimise objective (11) of Le Ny &
   Pappas on a demand sample, ``sum_j c(min_{s in S} T(s, z_j))``: the p-median
   with ``p = k`` restricted to the references: every ``k``-subset when they are
   few (:data:`EXACT_WORK`), else greedy addition, the fast interchange and
   variable neighbourhood search (:mod:`routing_svc.sa.interchange`);
2. the available vehicles matched to those posts at the least total travel time
   from where they are now (the linear assignment problem, scipy's
   ``linear_sum_assignment``).

Among posts of equal cost, the references the available vehicles already hold win.

With every vehicle of a type available the posts are all its references, still
matched at the least travel: a vehicle back from a job may take over the reference
that another one holds for it, rather than both driving. Posts change nothing:
they are an answer to read, not an event.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Generic

import numpy as np
from scipy.optimize import linear_sum_assignment

from routing_svc.sa.interchange import greedy_interchange, neighbourhood_search
from routing_svc.sa.live import Status, VehicleState
from routing_svc.sa.space import P
from routing_svc.types import FloatArray, IntArray

UNREACHABLE = 1e12
"""Stands in for an infinite travel time in the two problems (both need finite costs)."""

EXACT_WORK = 20_000_000
"""Subsets times sample targets up to which the posts are found by enumeration."""

SUBSETS_PER_CHUNK = 256
"""Subsets priced at once by the enumeration."""

CostMatrix = Callable[[list[P], list[P]], FloatArray]


@dataclass(frozen=True, slots=True)
class Post(Generic[P]):
    """Where one available vehicle should wait now.

    Attributes
    ----------
    vehicle : int
        The available vehicle (fleet index).
    reference_of : int
        The vehicle whose reference is the post (``vehicle`` itself: its own).
    position : P
        The post.
    time : float
        The vehicle's travel time from where it is now to the post.
    """

    vehicle: int
    reference_of: int
    position: P
    time: float


def _finite(costs: FloatArray) -> FloatArray:
    """``costs`` with infinite (unreachable) entries replaced by :data:`UNREACHABLE`."""
    return np.minimum(np.nan_to_num(costs, posinf=UNREACHABLE), UNREACHABLE)


def choose_posts(site_costs: FloatArray, k: int, *, exact_work: int = EXACT_WORK) -> IntArray:
    """The ``k`` sites (rows of ``site_costs``, service costs ``c(T)`` to each sample
    target) that minimise the sample's total cost, in ascending order; every site when
    ``k`` is their number.

    Exact (every subset, the first of equal cost in lexicographic order) while the
    subsets times the targets are at most ``exact_work``; beyond, a local optimum of
    the fast interchange improved by variable neighbourhood search.
    """
    n_sites, n_targets = site_costs.shape
    if k >= n_sites:
        return np.arange(n_sites, dtype=np.int64)
    costs = _finite(site_costs)
    if math.comb(n_sites, k) * n_targets <= exact_work:
        return _enumerated(costs, k)
    weights = np.ones(n_targets, dtype=np.float64)
    found = neighbourhood_search(costs, weights, greedy_interchange(costs, weights, k))
    return np.sort(found).astype(np.int64)


def _enumerated(costs: FloatArray, k: int) -> IntArray:
    """The best ``k``-subset of the rows by enumeration."""
    subsets = itertools.combinations(range(costs.shape[0]), k)
    best, best_value = np.arange(k, dtype=np.int64), math.inf
    while chunk := list(itertools.islice(subsets, SUBSETS_PER_CHUNK)):
        rows = np.array(chunk, dtype=np.int64)
        values = costs[rows].min(axis=1).sum(axis=1)
        i = int(np.argmin(values))
        if values[i] < best_value:
            best, best_value = rows[i], float(values[i])
    return best


def match_posts(travel: FloatArray) -> IntArray:
    """For each vehicle (row), the post (column) it holds: the assignment of least
    total travel time (square matrix)."""
    costs = _finite(travel)
    rows, columns = linear_sum_assignment(costs)
    matched = np.empty(costs.shape[0], dtype=np.int64)
    matched[rows] = columns
    return matched


def fleet_posts(
    cost_matrix: CostMatrix[P],
    *,
    references: Sequence[P],
    speeds: FloatArray,
    types: Sequence[str],
    states: Sequence[VehicleState[P]],
    sample: Sequence[P] | Mapping[str, Sequence[P]],
    power: float,
) -> list[Post[P]]:
    """Every available vehicle's post (see the module docstring).

    Parameters
    ----------
    cost_matrix
        Directed costs from sources to targets (the space's ``cost_matrix``).
    references, speeds, types, states
        Per vehicle: its reference, speed, type and live state.
    sample
        The demand sample (targets), or one per type (the targets that needed it, for a
        fleet that learns per type); empty: the references themselves, one each.
    power
        The objective's power ``q``, ``c(T) = T**q``.

    Returns
    -------
    list of Post
        One per available vehicle, in vehicle order.
    """
    posts: list[Post[P]] = []
    for kind in sorted(set(types)):
        own = sample.get(kind, ()) if isinstance(sample, Mapping) else sample
        demand = list(own) if own else list(references)
        of_kind = [i for i, t in enumerate(types) if t == kind]
        free = [i for i in of_kind if states[i].status is Status.AVAILABLE]
        if not free:
            continue
        # the available vehicles' own references first: among posts of equal cost
        # those they already hold win, so that nobody drives for nothing
        members = free + [i for i in of_kind if i not in free]
        sites = [references[i] for i in members]
        owners = np.array(members, dtype=np.int64)
        if len(free) < len(members):
            times = cost_matrix(sites, demand) / speeds[owners][:, None]
            chosen = choose_posts(times**power, len(free))
        else:
            chosen = np.arange(len(members), dtype=np.int64)
        here: list[P] = []
        for i in free:
            now = states[i].position
            here.append(references[i] if now is None else now)
        targets = [sites[int(c)] for c in chosen]
        travel = cost_matrix(here, targets) / speeds[free][:, None]
        for row, column in enumerate(match_posts(travel).tolist()):
            site = int(chosen[column])
            posts.append(
                Post(free[row], int(owners[site]), sites[site], float(travel[row, column]))
            )
    posts.sort(key=lambda post: post.vehicle)
    return posts
