"""Junctions along a route and the candidate references around a sample of targets.

Two questions of the learning rules of :mod:`routing_svc.sa.held_step` and
:mod:`routing_svc.sa.consolidation`, answered on a :class:`CompiledNetwork`:

- :func:`junction_ahead`: the first junction that a reference meets when it
  follows a route toward a target, and the cost to it. A junction is the end of
  an edge, ``(e, len(e))``, where a waiting vehicle still has every turn of
  the junction; a reference that moves past it gives them up, which is where
  the expected cost ``J`` jumps. It also names the direction a target pulls.
- :func:`candidate_references`: the positions a consolidation may open, the
  targets of the sample and the ends of their edges (Hakimi's demand points
  plus vertices, see :mod:`routing_svc.optimum.candidates`), with the given
  positions first.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from routing_svc.network.compile import CompiledNetwork
from routing_svc.network.costs import EdgeCosts
from routing_svc.types import NetPosition

__all__ = ["candidate_references", "junction_ahead"]


def junction_ahead(
    network: CompiledNetwork,
    costs: EdgeCosts,
    position: NetPosition,
    route: Sequence[int],
) -> tuple[NetPosition, float] | None:
    """The first junction strictly ahead of ``position`` along ``route``, and its cost.

    ``route`` is the mover's edge path from the search: its first edge is the
    position's edge, or the position's twin edge when the vehicle leaves the other
    way. The junction is the end of that first edge (even when the target lies on
    it, before its end), or, for a position already at that end, the end of the
    route's next edge; ``None`` for a position at the end of a one-edge route.
    """
    first = int(route[0])
    length = network.length
    if first == position.edge:
        offset = position.offset
    else:  # leaving the other way: the same place on the twin edge
        offset = float(length[first]) * (1.0 - position.offset / float(length[position.edge]))
        offset = min(max(offset, 0.0), float(length[first]))
    rest = float(length[first]) - offset
    if rest > 0.0:
        return NetPosition(first, float(length[first])), rest * float(costs.rate[first])
    if len(route) < 2:
        return None
    nxt = int(route[1])
    return NetPosition(nxt, float(length[nxt])), float(costs.cost[nxt])


def candidate_references(
    network: CompiledNetwork,
    sample: Sequence[NetPosition],
    fixed: Sequence[NetPosition],
) -> list[NetPosition]:
    """``fixed`` (in order), then the targets of ``sample`` and the ends of their edges.

    Without repeats. The demand points and the edge ends contain an optimal
    p-median of the sample (:mod:`routing_svc.optimum.candidates`); ``fixed``
    (the current references) lets a solver start from where the fleet is.
    """
    edges = np.unique(np.fromiter((z.edge for z in sample), dtype=np.int64, count=len(sample)))
    ends = [NetPosition(int(e), float(network.length[e])) for e in edges.tolist()]
    return list(dict.fromkeys([*fixed, *sample, *ends]))
