"""Targets anywhere along the road, and the fine model that prices them.

A demand of :mod:`routing_svc.demand.network` puts one atom at the middle of each
piece of road (at most ``DEFAULT_SPACING`` metres) and draws targets at the atoms
only. A user's calls fall anywhere: :class:`ContinuousDemand` draws an atom, then a
uniform offset within its piece, so that no two targets coincide. Its ``positions``
and ``weights`` are the fine model that prices a fleet against that demand
(``CONTINUOUS_PARTS`` atoms a piece, each at the middle of its part: the expected
cost of objective (11) integrated along each piece by the midpoint rule).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from routing_svc.demand import DemandDistribution
from routing_svc.demand.network import DEFAULT_SPACING, piece_counts
from routing_svc.errors import InvalidInput
from routing_svc.network import CompiledNetwork
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
