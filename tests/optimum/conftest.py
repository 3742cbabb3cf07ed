"""Cost models, brute-force references and the DRT network for the optimum tests."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
import sumo

from routing_svc.network import CompiledNetwork, load_network
from routing_svc.types import FloatArray, PlanePosition

DRT_NET = Path(sumo.SUMO_HOME) / "tools" / "game" / "DRT" / "osm.net.xml"


class PlaneCosts:
    """Euclidean distances, computed with plain numpy."""

    def cost_matrix(
        self, sources: Sequence[PlanePosition], targets: Sequence[PlanePosition]
    ) -> FloatArray:
        a = np.asarray(sources, dtype=np.float64).reshape(-1, 2)
        b = np.asarray(targets, dtype=np.float64).reshape(-1, 2)
        return np.asarray(np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1]))


class WindyCosts:
    """A directed cost on the plane: travelling east is cheaper than west.

    ``d(a, b) = |b - a| - 0.5 (b.x - a.x)``, so ``d(a, b) != d(b, a)``.
    """

    @staticmethod
    def pair(a: PlanePosition, b: PlanePosition) -> float:
        return math.hypot(b.x - a.x, b.y - a.y) - 0.5 * (b.x - a.x)

    def cost_matrix(
        self, sources: Sequence[PlanePosition], targets: Sequence[PlanePosition]
    ) -> FloatArray:
        return np.array([[self.pair(a, b) for b in targets] for a in sources]).reshape(
            len(sources), len(targets)
        )


def brute_force_pmedian(costs: FloatArray, weights: FloatArray, p: int) -> float:
    """Smallest ``sum_j w_j min_{i in S} c_ij`` over every ``p``-subset ``S``."""
    best = math.inf
    subsets = np.array(list(itertools.combinations(range(costs.shape[0]), p)), dtype=np.int64)
    for chunk in np.array_split(subsets, max(1, len(subsets) // 2000)):
        values = costs[chunk].min(axis=1) @ weights
        best = min(best, float(values.min()))
    return best


def all_subset_values(
    costs: FloatArray, weights: FloatArray, p: int
) -> dict[tuple[int, ...], float]:
    """``F(S)`` for every ``p``-subset ``S`` (small instances only)."""
    return {
        s: float(weights @ costs[list(s)].min(axis=0))
        for s in itertools.combinations(range(costs.shape[0]), p)
    }


@pytest.fixture(scope="session")
def drt_network(tmp_path_factory: pytest.TempPathFactory) -> CompiledNetwork:
    """The DRT district of the eclipse-sumo package, compiled into a private cache."""
    return load_network(DRT_NET, cache_dir=tmp_path_factory.mktemp("optimum-cache"))
