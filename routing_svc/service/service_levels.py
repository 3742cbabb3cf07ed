"""Service levels of a fleet: how soon the dispatched vehicles complete its targets.

For every target the completion cost is the arrival of the last dispatched
vehicle (:attr:`routing_svc.sa.live.Sent.completion`); a target that could not
be dispatched in full (``queued`` or ``partial``) has none and counts as beyond
every threshold. Over all targets and over the most recent ``window`` of them
this reports the fraction completed within each of the fleet's thresholds and
the 50th, 90th and 95th percentiles (nearest rank; ``None`` where the rank
falls on a target without a completion).

The recent window keeps its costs, so its percentiles are exact. Over all
targets the costs go into a histogram of logarithmic bins
(:data:`BIN_RATIO` apart), and a percentile is the upper edge of its bin,
within that ratio of the exact value. Everything is derived from the event log
in event order, so a replay gives the same numbers.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from typing import Any

DEFAULT_THRESHOLDS = (300.0, 600.0, 900.0)
"""Thresholds (cost units) of a fleet created without its own."""

PERCENTILES = (50, 90, 95)

BIN_RATIO = 1.01
"""Ratio of consecutive bin edges of the all-targets histogram (percentiles within 1 %)."""

_LOG_RATIO = math.log(BIN_RATIO)
_ZERO_BIN = -(10**6)
"""The bin of a zero cost (below the bin of the smallest positive float)."""


def _bin(cost: float) -> int:
    """The histogram bin of a cost: ``floor(log(cost) / log(ratio))``, or the zero bin."""
    return _ZERO_BIN if cost <= 0.0 else math.floor(math.log(cost) / _LOG_RATIO)


def _upper_edge(index: int) -> float:
    return 0.0 if index == _ZERO_BIN else BIN_RATIO ** (index + 1)


def nearest_rank(values: Sequence[float | None], percentile: int) -> float | None:
    """The nearest-rank percentile of ``values`` (``None`` sorts after every cost)."""
    if not values:
        return None
    ordered = sorted(values, key=lambda v: math.inf if v is None else v)
    rank = max(1, math.ceil(percentile / 100 * len(ordered)))
    return ordered[rank - 1]


class ServiceLevels:
    """Running service levels of one fleet (see the module's docstring)."""

    def __init__(self, thresholds: Iterable[float], *, window: int) -> None:
        self.thresholds = tuple(float(t) for t in thresholds)
        self.total = 0
        self.undispatched = 0
        self.within = [0] * len(self.thresholds)
        self.bins: dict[int, int] = {}
        self.recent: deque[float | None] = deque(maxlen=window)

    def record(self, completion: float | None) -> None:
        """Count one target with its completion cost (``None``: not dispatched in full)."""
        self.total += 1
        self.recent.append(completion)
        if completion is None:
            self.undispatched += 1
            return
        for i, limit in enumerate(self.thresholds):
            if completion <= limit:
                self.within[i] += 1
        index = _bin(completion)
        self.bins[index] = self.bins.get(index, 0) + 1

    def _all_percentile(self, percentile: int) -> float | None:
        if not self.total:
            return None
        rank = max(1, math.ceil(percentile / 100 * self.total))
        seen = 0
        for index in sorted(self.bins):
            seen += self.bins[index]
            if seen >= rank:
                return _upper_edge(index)
        return None  # the rank falls on the targets without a completion

    def report(self) -> dict[str, Any]:
        """The levels as the API shows them."""
        recent = list(self.recent)
        recent_done = [c for c in recent if c is not None]
        return {
            "thresholds": list(self.thresholds),
            "all": {
                "targets": self.total,
                "undispatched": self.undispatched,
                "within": [n / self.total if self.total else None for n in self.within],
                "percentiles": {f"p{p}": self._all_percentile(p) for p in PERCENTILES},
            },
            "recent": {
                "targets": len(recent),
                "window": self.recent.maxlen,
                "undispatched": len(recent) - len(recent_done),
                "within": [
                    sum(1 for c in recent_done if c <= limit) / len(recent) if recent else None
                    for limit in self.thresholds
                ],
                "percentiles": {f"p{p}": nearest_rank(recent, p) for p in PERCENTILES},
            },
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready state (bins as ``[index, count]`` pairs in index order)."""
        return {
            "total": self.total,
            "undispatched": self.undispatched,
            "within": list(self.within),
            "bins": [[i, self.bins[i]] for i in sorted(self.bins)],
            "recent": list(self.recent),
        }

    def restore(self, data: dict[str, Any]) -> None:
        """Load :meth:`to_dict` output."""
        within = [int(n) for n in data["within"]]
        if len(within) != len(self.thresholds):
            raise ValueError("stored service levels have other thresholds")
        self.total = int(data["total"])
        self.undispatched = int(data["undispatched"])
        self.within = within
        self.bins = {int(i): int(n) for i, n in data["bins"]}
        self.recent.clear()
        self.recent.extend(None if c is None else float(c) for c in data["recent"])
