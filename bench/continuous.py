"""Targets anywhere along the road, and the fine model that prices them.

A demand of :mod:`routing_svc.demand.network` puts one atom at the middle of each
piece of road (at most ``DEFAULT_SPACING`` metres) and draws targets at the atoms
only. A user's calls fall anywhere: :class:`ContinuousDemand` draws an atom, then a
uniform offset within its piece, so that no two targets coincide. Its ``positions``
and ``weights`` are the fine model that prices a fleet against that demand
(``CONTINUOUS_PARTS`` atoms a piece, each at the middle of its part: the expected
cost of objective (11) integrated along each piece by the midpoint rule).

The midpoint rule is exact for a vehicle outside a piece, where the cost to a point of
the piece grows linearly along it; for a vehicle inside a piece, it charges the loop
round the block to a whole part behind the vehicle. :func:`priced_along` integrates
each piece exactly (objective (11) with ``q = 1``), and :func:`piece_starts` gives
candidate sites whose cost to each piece is exactly its cost to the piece's middle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.demand.network import DEFAULT_SPACING, piece_counts
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork, RoadSpace
from routing_svc.types import FloatArray, NetPosition

CONTINUOUS_PARTS = 5
"""Atoms of the fine model per piece of the drawn demand."""


@dataclass(frozen=True, eq=False)
class ContinuousDemand(DemandDistribution[NetPosition]):
    """The fine model of ``coarse`` spread along its pieces; draws anywhere in them.

    Attributes
    ----------
    coarse : DemandDistribution
        The demand whose atoms are drawn.
    pieces : FloatArray
        The length of each coarse atom's piece of road.
    lengths : FloatArray
        The length of each coarse atom's edge.
    """

    coarse: DemandDistribution[NetPosition] = field(kw_only=True, repr=False)
    pieces: FloatArray = field(kw_only=True, repr=False)
    lengths: FloatArray = field(kw_only=True, repr=False)

    def sample(self, rng: np.random.Generator, n: int) -> list[NetPosition]:
        """``n`` targets: an atom of :attr:`coarse` each, moved uniformly within its piece.

        Two uniform numbers a target, in draw order, so that the first ``k`` of ``n``
        targets are the ``k`` targets drawn from the same generator state."""
        if n < 0:
            raise InvalidInput(f"cannot draw a negative number of targets ({n})")
        draws = rng.random((n, 2))
        cdf = np.cumsum(self.coarse.weights)
        picks = np.minimum(np.searchsorted(cdf / cdf[-1], draws[:, 0], side="right"), cdf.size - 1)
        shifts = (draws[:, 1] - 0.5) * self.pieces[picks]
        out = []
        for j, shift in zip(picks.tolist(), shifts.tolist(), strict=True):
            z = self.coarse.positions[j]
            out.append(NetPosition(z.edge, min(max(z.offset + shift, 0.0), self.lengths[j])))
        return out


def continuous(
    network: CompiledNetwork,
    coarse: DemandDistribution[NetPosition],
    *,
    parts: int = CONTINUOUS_PARTS,
    spacing: float = DEFAULT_SPACING,
) -> ContinuousDemand:
    """``coarse`` (atoms at the middles of pieces of at most ``spacing`` metres) spread
    along its pieces: ``parts`` atoms of the fine model a piece, each of a ``parts``-th
    of its weight."""
    edges = np.array([z.edge for z in coarse.positions], dtype=np.int64)
    offsets = np.array([z.offset for z in coarse.positions])
    lengths = network.length[edges].astype(np.float64)
    pieces = lengths / piece_counts(lengths, spacing)
    middles = (np.arange(parts) + 0.5) / parts - 0.5
    fine = np.clip(offsets[:, None] + middles[None, :] * pieces[:, None], 0.0, lengths[:, None])
    positions = tuple(
        NetPosition(int(e), float(x))
        for e, row in zip(edges.tolist(), fine.tolist(), strict=True)
        for x in row
    )
    weights = np.repeat(coarse.weights / parts, parts)
    return ContinuousDemand(
        f"{coarse.name}, anywhere along the road",
        positions,
        weights / math.fsum(weights.tolist()),
        coarse=coarse,
        pieces=pieces,
        lengths=lengths,
    )


def piece_bounds(demand: ContinuousDemand) -> tuple[FloatArray, FloatArray]:
    """Where each coarse atom's piece of road starts and ends, as offsets on its edge."""
    offsets = np.array([z.offset for z in demand.coarse.positions])
    half = demand.pieces / 2.0
    return (
        np.clip(offsets - half, 0.0, demand.lengths),
        np.clip(offsets + half, 0.0, demand.lengths),
    )


def piece_starts(demand: ContinuousDemand, sites: list[NetPosition]) -> list[NetPosition]:
    """``sites`` with each coarse atom moved to the start of its piece, without repeats.

    From a site at a piece's start (or at an edge's end) the cost to a point of any
    piece grows linearly along that piece, so the cost to the piece's middle is the
    exact mean over the piece: a p-median of the coarse atoms over these sites is
    priced exactly."""
    start = piece_bounds(demand)[0]
    row = {z: j for j, z in enumerate(demand.coarse.positions)}
    moved = [NetPosition(z.edge, float(start[row[z]])) if z in row else z for z in sites]
    return list(dict.fromkeys(moved))


def priced_along(space: RoadSpace, positions: list[NetPosition], demand: ContinuousDemand) -> float:
    """The exact expected cost of objective (11) (``q = 1``, unit speeds) of vehicles at
    ``positions`` for targets drawn uniformly along each piece of ``demand``.

    On a piece ``[a, b]`` the cost from a vehicle to ``u`` is ``K + r u`` (``r`` the
    edge's cost per metre), except past a point ``x`` of the piece where the vehicle
    (or its twin on a two-way street) stands, from which it is ``r (u - x)``. The two
    ends of each piece give ``K`` and ``x``; the mean of the smallest cost over the
    piece is then integrated in closed form.
    """
    if not positions:
        raise InvalidInput("priced_along needs at least one position")
    coarse = demand.coarse
    start, end = piece_bounds(demand)
    edges = np.array([z.edge for z in coarse.positions], dtype=np.int64)
    rate = space.edge_costs.rate[edges]
    at_start = space.cost_matrix(
        positions, [NetPosition(int(e), float(a)) for e, a in zip(edges, start, strict=True)]
    )
    at_end = space.cost_matrix(
        positions, [NetPosition(int(e), float(b)) for e, b in zip(edges, end, strict=True)]
    )
    span = end - start
    loop = at_start - rate * start  # K: the cost is K + r u until a vehicle's point
    linear = at_end >= at_start + rate * span - 1e-9 * (1.0 + at_end)
    floor = loop.min(axis=0)
    mean = floor + rate * (start + end) / 2.0
    for j in np.flatnonzero(~linear.all(axis=0) & (span > 0.0)).tolist():
        r, a, b = float(rate[j]), float(start[j]), float(end[j])
        points = sorted(b - at_end[i, j] / r for i in np.flatnonzero(~linear[:, j]).tolist())
        points = [min(max(x, a), b) for x in points]
        first = points[0]
        total = float(floor[j]) * (first - a) + r * (first * first - a * a) / 2.0
        for x, nxt in zip(points, [*points[1:], b], strict=True):
            total += r * (nxt - x) ** 2 / 2.0
        mean[j] = total / (b - a)
    weights = coarse.weights / math.fsum(coarse.weights.tolist())
    return float(weights @ mean)
