"""Moving a position along the road network: along a route, or at random.

A route is the array of edge indices that a vehicle drives, from its own
edge to the target's edge (see :mod:`routing_svc.network.search`). Walking it
spends cost in the order it is driven: the rest of the first edge, every
intermediate edge, then the target edge up to the target's offset. A route of
one edge is the same-edge case (the target is ahead on the vehicle's edge).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from routing_svc.errors import InvalidInput
from routing_svc.network.compile import CompiledNetwork
from routing_svc.network.costs import EdgeCosts
from routing_svc.network.moves import walk_one_edge
from routing_svc.types import FloatArray, Int32Array, IntArray, NetPosition

__all__ = ["check_route", "random_walk", "walk_route", "walk_spend"]


def _check_amount(amount: float) -> float:
    if isinstance(amount, bool) or not isinstance(amount, int | float | np.floating):
        raise InvalidInput("amount must be a number")
    value = float(amount)
    if not (math.isfinite(value) and value >= 0.0):
        raise InvalidInput(f"amount must be finite and >= 0, got {amount!r}")
    return value


def check_route(
    network: CompiledNetwork, position: NetPosition, target: NetPosition, route: object
) -> IntArray:
    """The route as an edge-index array, checked to lead from ``position`` to ``target``.

    Raises
    ------
    InvalidInput
        If ``route`` is not a 1-d integer array of connected edges from the
        position's edge to the target's edge.
    """
    if not isinstance(route, np.ndarray) or route.ndim != 1 or route.shape[0] == 0:
        raise InvalidInput("route must be a non-empty 1-d array of edge indices")
    if not np.issubdtype(route.dtype, np.integer):
        raise InvalidInput("route must hold integer edge indices")
    edges = route.astype(np.int64)
    if int(edges[0]) != position.edge or int(edges[-1]) != target.edge:
        raise InvalidInput("route does not lead from the position's edge to the target's edge")
    if edges.shape[0] == 1 and position.offset > target.offset:
        raise InvalidInput("a one-edge route needs the target ahead of the position")
    problem = _route_problem(network.fwd_indptr, network.fwd_indices, edges)
    if problem == _OUT_OF_RANGE:
        raise InvalidInput("route holds an edge index out of range")
    if problem == _NOT_CONNECTED:
        raise InvalidInput("route holds consecutive edges that are not connected")
    return edges


_OUT_OF_RANGE = 1
_NOT_CONNECTED = 2


@njit(cache=True)
def _route_problem(fwd_indptr: Int32Array, fwd_indices: Int32Array, edges: IntArray) -> int:
    """0 if every edge of ``edges`` is in range and each is a successor of the one
    before it; else :data:`_OUT_OF_RANGE` or :data:`_NOT_CONNECTED` (range first)."""
    n_edges = fwd_indptr.shape[0] - 1
    for e in edges:
        if e < 0 or e >= n_edges:
            return _OUT_OF_RANGE
    for k in range(edges.shape[0] - 1):
        tail, head = edges[k], edges[k + 1]
        found = False
        for j in range(fwd_indptr[tail], fwd_indptr[tail + 1]):
            if fwd_indices[j] == head:
                found = True
                break
        if not found:
            return _NOT_CONNECTED
    return 0


@njit(cache=True)
def walk_spend(
    length: FloatArray,
    cost: FloatArray,
    rate: FloatArray,
    route: IntArray,
    start_offset: float,
    target_offset: float,
    spend: float,
) -> tuple[int, float]:
    """Where a cost ``spend`` along ``route`` (two edges or more) ends: ``(k, offset)``
    on ``route[k]``, or ``k = -1`` at the target.

    The costs spent are the rest of the first edge, the intermediate edges and
    the target edge's part, summed in the order driven; the route's total is
    also summed in the order the search sums it (from the target back), so
    that an ``amount`` equal to the cost that :meth:`RoadSpace.assign`
    reported lands exactly on the target.
    """
    m = route.shape[0]
    first = route[0]
    last = route[m - 1]
    segments = np.empty(m)
    segments[0] = (length[first] - start_offset) * rate[first]
    for j in range(1, m - 1):
        segments[j] = cost[route[j]]
    segments[m - 1] = target_offset * rate[last]
    reached = np.empty(m)
    total = segments[0]
    reached[0] = total
    for j in range(1, m):
        total = total + segments[j]
        reached[j] = total
    from_end = segments[m - 1]
    for j in range(m - 2, 0, -1):
        from_end = from_end + segments[j]
    if spend >= reached[m - 1] or spend >= from_end + segments[0]:
        return -1, target_offset
    k = 0
    while k < m and reached[k] <= spend:  # the first k with reached[k] > spend
        k += 1
    if k == 0:
        return 0, min(start_offset + spend / rate[first], length[first])
    edge = route[k]
    limit = target_offset if k == m - 1 else length[edge]
    return k, min((spend - reached[k - 1]) / rate[edge], limit)


def walk_route(
    network: CompiledNetwork,
    costs: EdgeCosts,
    position: NetPosition,
    target: NetPosition,
    route: IntArray,
    amount: float,
) -> NetPosition:
    """Move ``position`` a cost ``amount`` along ``route`` toward ``target``.

    Parameters
    ----------
    network, costs : CompiledNetwork, EdgeCosts
        The graph and its edge costs.
    position, target : NetPosition
        Start and end of the route.
    route : IntArray
        Checked route (see :func:`check_route`).
    amount : float
        Cost to spend, >= 0; at least the route's cost gives exactly ``target``.

    Returns
    -------
    NetPosition
        The new position; it never passes the target.
    """
    spend = _check_amount(amount)
    rate = costs.rate
    if route.shape[0] == 1:
        reached, offset = walk_one_edge(
            rate, target.edge, float(position.offset), float(target.offset), spend
        )
        return target if reached else NetPosition(target.edge, float(offset))
    k, offset = walk_spend(
        network.length, costs.cost, rate, route, float(position.offset), float(target.offset), spend
    )
    if k < 0:
        return target
    return NetPosition(int(route[k]), float(offset))


def random_walk(
    network: CompiledNetwork,
    costs: EdgeCosts,
    position: NetPosition,
    amount: float,
    rng: np.random.Generator,
) -> NetPosition:
    """Drive a cost ``amount`` forward from ``position``, turning at random.

    At the end of each edge the walk continues on a successor edge drawn
    uniformly with ``rng``; it stops early only at an edge without successors.

    Raises
    ------
    InvalidInput
        If ``amount`` is negative, not finite, or larger than the cost of all
        edges of the network together.
    """
    spend = _check_amount(amount)
    if spend > float(costs.cost.sum()):
        raise InvalidInput("amount exceeds the cost of the whole network")
    edge, offset = int(position.edge), float(position.offset)
    while True:
        length = float(network.length[edge])
        to_end = (length - offset) * costs.rate[edge]
        if spend <= to_end:
            return NetPosition(edge, float(min(offset + spend / costs.rate[edge], length)))
        spend -= to_end
        lo, hi = int(network.fwd_indptr[edge]), int(network.fwd_indptr[edge + 1])
        if lo == hi:
            return NetPosition(edge, length)
        edge, offset = int(network.fwd_indices[lo + int(rng.integers(hi - lo))]), 0.0
