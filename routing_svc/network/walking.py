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
import numpy.typing as npt

from routing_svc.errors import InvalidInput
from routing_svc.network.compile import CompiledNetwork
from routing_svc.network.costs import EdgeCosts
from routing_svc.types import NetPosition

__all__ = ["check_route", "random_walk", "walk_route"]

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]


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
    if ((edges < 0) | (edges >= network.n_edges)).any():
        raise InvalidInput("route holds an edge index out of range")
    if not network.has_arcs(edges[:-1], edges[1:]):
        raise InvalidInput("route holds consecutive edges that are not connected")
    return edges


def _route_cost(segments: FloatArray) -> float:
    """The route's cost summed in the order the search sums it (from the target back).

    ``segments`` are the costs of the first edge's rest, the intermediate
    edges and the target edge's part. Summing them the same way makes an
    ``amount`` equal to the cost that :meth:`RoadSpace.assign` reported land
    exactly on the target.
    """
    from_end = np.cumsum(segments[:0:-1])[-1]
    return float(from_end + segments[0])


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
        t_rate = rate[target.edge]
        if spend >= (target.offset - position.offset) * t_rate:
            return target
        return NetPosition(target.edge, float(min(position.offset + spend / t_rate, target.offset)))
    first = int(route[0])
    segments = np.empty(route.shape[0])
    segments[0] = (network.length[first] - position.offset) * rate[first]
    segments[1:-1] = costs.cost[route[1:-1]]
    segments[-1] = target.offset * rate[target.edge]
    reached = np.cumsum(segments)
    if spend >= reached[-1] or spend >= _route_cost(segments):
        return target
    k = int(np.searchsorted(reached, spend, side="right"))
    if k == 0:
        offset = min(position.offset + spend / rate[first], network.length[first])
        return NetPosition(first, float(offset))
    edge = int(route[k])
    limit = target.offset if k == route.shape[0] - 1 else network.length[edge]
    return NetPosition(edge, float(min((spend - reached[k - 1]) / rate[edge], limit)))


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
