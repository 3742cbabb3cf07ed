"""Seeded workloads shared by the reliability tests."""

from __future__ import annotations

from typing import Any

import numpy as np

from tests.service.test_api import NET, edge, fleet_body

__all__ = ["fleet_body", "target_stream"]


def target_stream(seed: int, n: int) -> list[dict[str, Any]]:
    """``n`` targets on random usable edges, at random offsets along them."""
    rng = np.random.default_rng(seed)
    out = []
    for e in rng.integers(NET.n_edges, size=n):
        offset = float(rng.uniform(0.0, float(NET.length[int(e)])))
        out.append({"position": {"edge": edge(int(e)), "offset": offset}})
    return out
