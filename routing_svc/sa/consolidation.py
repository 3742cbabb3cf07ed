"""Consolidation: the p-median of recent targets, kept only where it serves unseen ones better.

A first-order rule keeps the local minima of online k-means: vehicles that
never win a target, the wrong number of vehicles per hotspot, and on a
directed network references stranded past a junction. From time to time the
``consolidating`` fleet therefore solves the batch problem on a bounded
reservoir of its most recent targets ``z_1 .. z_m``:

.. math:: \\min_{S, |S| = p} \\sum_j c\\bigl(\\min_{s \\in S} d(s, z_j)\\bigr),

objective (11) of Le Ny & Pappas on the empirical distribution, over the
candidate references of the sample (its targets and the ends of their edges,
Hakimi's finite dominating set) by greedy addition and Whitaker's fast
interchange (:mod:`routing_svc.sa.interchange`), started from the current
references, from the last accepted ones and from scratch.

A p-median of ``m`` targets fits their noise: taken blindly it would pull a
fleet that already stands at the optimum away from it. So the reservoir is
split. The solver sees every other target (the *fit* half); the configuration
it finds, or the last accepted one, replaces the current references only if it
serves the other half (*held out*) better by more than ``confidence`` standard
errors of the paired differences. Accepted, it is polished on the whole
reservoir; each vehicle's step counter restarts at the number of reservoir
targets it now serves, so that the paper's steps (eq. (10)) go on at the size
of a fleet that has seen them.

Consolidations follow the demand's clock: ``first`` targets into an *epoch*, then
each time the targets seen in the epoch have grown by the factor ``growth``, the
period capped at ``longest``. The mean cost of
each block of targets is compared with the held-out cost of the references at
the last consolidation; a block that costs ``shift_ratio`` times more starts a
new epoch (the demand moved): the reservoir keeps that block only and the
schedule starts again.

Each consolidation is recorded with the target that triggered it
(:class:`Consolidation`), so that replay applies it without solving again.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Generic, Protocol, runtime_checkable

import numpy as np

from routing_svc.errors import InvalidInput
from routing_svc.sa.interchange import fast_interchange, greedy
from routing_svc.sa.space import P
from routing_svc.types import FloatArray, IntArray


@dataclass(frozen=True, slots=True)
class ConsolidationPolicy:
    """When and how a ``consolidating`` fleet consolidates (see the module docstring).

    Attributes
    ----------
    reservoir : int
        The most recent targets kept (any one vehicle required).
    first : int
        Targets into an epoch of the first consolidation; the period then doubles.
    growth : float
        Each period is ``growth - 1`` times the targets seen in the epoch (at least
        ``first``).
    longest : int
        The longest period between two consolidations.
    confidence : float
        Standard errors by which the held-out half must prefer a new configuration.
    block : int
        Targets per block of the shift test.
    shift_ratio : float
        A block whose mean cost exceeds this times the held-out cost of the
        references starts a new epoch.
    """

    reservoir: int = 4000
    first: int = 250
    growth: float = 1.5
    longest: int = 8000
    confidence: float = 1.0
    block: int = 250
    shift_ratio: float = 1.25

    def __post_init__(self) -> None:
        for name in ("reservoir", "first", "longest", "block"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 2:
                raise InvalidInput(f"consolidation {name} must be an integer >= 2, got {value!r}")
        if self.block > self.reservoir:
            raise InvalidInput("the consolidation block must fit in the reservoir")
        if not (math.isfinite(self.growth) and self.growth > 1.0):
            raise InvalidInput("consolidation growth must be a finite number > 1")
        if not (math.isfinite(self.confidence) and self.confidence >= 0.0):
            raise InvalidInput("consolidation confidence must be a finite number >= 0")
        if not (math.isfinite(self.shift_ratio) and self.shift_ratio > 1.0):
            raise InvalidInput("consolidation shift_ratio must be a finite number > 1")

    def to_dict(self) -> dict[str, Any]:
        return {
            "reservoir": self.reservoir,
            "first": self.first,
            "growth": self.growth,
            "longest": self.longest,
            "confidence": self.confidence,
            "block": self.block,
            "shift_ratio": self.shift_ratio,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ConsolidationPolicy:
        if not isinstance(data, dict):
            raise InvalidInput("consolidation must be an object")
        unknown = set(data) - set(cls().to_dict())
        if unknown:
            raise InvalidInput(f"unknown consolidation fields: {sorted(unknown)}")
        return cls(**data)

    def next_after(self, *, now: int, epoch: int) -> int:
        """The target count of the next consolidation after one at ``now``."""
        period = math.ceil((now - epoch) * (self.growth - 1.0))
        return now + min(max(period, self.first), self.longest)


@dataclass(frozen=True, slots=True)
class Consolidation(Generic[P]):
    """What one consolidation decided (recorded, so replay need not solve again).

    Attributes
    ----------
    accepted : bool
        Whether the references changed.
    positions : tuple
        Every vehicle's reference afterwards (in the fleet's id order).
    updates : tuple of int
        Every vehicle's step counter afterwards.
    sample : int
        Targets in the reservoir.
    held_out_before, held_out_after : float
        Mean cost ``c(T)`` of the held-out half from the references before and
        after; ``held_out_after`` is the baseline of the shift test.
    """

    accepted: bool
    positions: tuple[P, ...]
    updates: tuple[int, ...]
    sample: int
    held_out_before: float
    held_out_after: float

    def to_dict(self, encode: Callable[[P], dict[str, object]]) -> dict[str, Any]:
        return {
            "accepted": self.accepted,
            "positions": [encode(p) for p in self.positions],
            "updates": list(self.updates),
            "sample": self.sample,
            "held_out_before": self.held_out_before,
            "held_out_after": self.held_out_after,
        }

    @classmethod
    def from_dict(
        cls, data: dict[str, Any], decode: Callable[[dict[str, object]], P]
    ) -> Consolidation[P]:
        try:
            return cls(
                accepted=bool(data["accepted"]),
                positions=tuple(decode(p) for p in data["positions"]),
                updates=tuple(int(u) for u in data["updates"]),
                sample=int(data["sample"]),
                held_out_before=float(data["held_out_before"]),
                held_out_after=float(data["held_out_after"]),
            )
        except (KeyError, TypeError, ValueError):
            raise InvalidInput("a recorded consolidation is malformed") from None


@runtime_checkable
class SampleSpace(Protocol[P]):
    """What a consolidation needs of a space: candidates and a cost matrix."""

    def candidate_references(self, sample: Sequence[P], fixed: Sequence[P]) -> list[P]:
        """``fixed`` first, then candidate references for ``sample``, without repeats."""
        ...

    def cost_matrix(self, sources: list[P], targets: list[P]) -> FloatArray:
        """Directed costs, shape ``(len(sources), len(targets))``."""
        ...


def consolidate(
    space: SampleSpace[P],
    positions: Sequence[P],
    anchor: Sequence[P],
    reservoir: Sequence[P],
    *,
    power: float,
    confidence: float,
    updates: Sequence[int],
) -> Consolidation[P]:
    """Solve the p-median of the fit half, test it on the held-out half, polish it on all.

    Parameters
    ----------
    space : SampleSpace
        The space (identical vehicles: costs are not divided by speeds).
    positions : sequence
        The current references, in the fleet's id order.
    anchor : sequence
        The last accepted references (a second start, and a second challenger).
    reservoir : sequence
        The recent targets, oldest first; even places fit, odd places test.
    power : float
        ``q`` of the service cost ``c(T) = T**q``.
    confidence : float
        Standard errors of the held-out test.
    updates : sequence of int
        The step counters, returned unchanged when nothing is accepted.
    """
    p = len(positions)
    if len(reservoir) < 2 or len(anchor) != p or len(updates) != p:
        raise InvalidInput("a consolidation needs two targets and one anchor per vehicle")
    targets = list(dict.fromkeys(reservoir))
    column = {z: j for j, z in enumerate(targets)}
    places = np.fromiter((column[z] for z in reservoir), dtype=np.int64, count=len(reservoir))
    fit_weight = np.bincount(places[0::2], minlength=len(targets)).astype(np.float64)
    held_weight = np.bincount(places[1::2], minlength=len(targets)).astype(np.float64)
    fit_sample = [targets[j] for j in np.flatnonzero(fit_weight).tolist()]
    sites = space.candidate_references(fit_sample, [*positions, *anchor])
    row = {s: i for i, s in enumerate(sites)}
    costs = np.asarray(space.cost_matrix(sites, targets), dtype=np.float64) ** power
    current = _distinct(np.array([row[x] for x in positions], dtype=np.int64), len(sites))
    anchored = _distinct(np.array([row[x] for x in anchor], dtype=np.int64), len(sites))
    fitted = _best_fit(costs, fit_weight, [current, anchored])
    if _total(costs, held_weight, anchored) < _total(costs, held_weight, fitted):
        fitted = anchored
    held = held_weight > 0
    before = costs[current][:, held].min(axis=0)
    after = costs[fitted][:, held].min(axis=0)
    weights = held_weight[held]
    total = float(weights.sum())
    held_before = float(weights @ before) / total
    difference = after - before
    mean = float(weights @ difference) / total
    spread = math.sqrt(max(float(weights @ (difference - mean) ** 2), 0.0) / total / total)
    if not mean < -confidence * spread or not mean < 0.0:
        unchanged = tuple(positions)
        return Consolidation(
            False, unchanged, tuple(updates), len(reservoir), held_before, held_before
        )
    weight = fit_weight + held_weight
    chosen = fast_interchange(costs, weight, fitted)
    ordered = _pair(current, chosen)
    owner = costs[ordered].argmin(axis=0)
    served = np.bincount(owner, weights=weight, minlength=p)
    held_after = float(weights @ costs[ordered][:, held].min(axis=0)) / total
    return Consolidation(
        True,
        tuple(sites[i] for i in ordered.tolist()),
        tuple(round(s) for s in served.tolist()),
        len(reservoir),
        held_before,
        held_after,
    )


def _distinct(rows: IntArray, n_sites: int) -> IntArray:
    """``rows`` with repeats replaced by the next free row (references that coincide)."""
    taken: set[int] = set()
    out = rows.copy()
    for k, r in enumerate(rows.tolist()):
        while r in taken:
            r = (r + 1) % n_sites
        taken.add(r)
        out[k] = r
    return out


def _best_fit(costs: FloatArray, weight: FloatArray, starts: list[IntArray]) -> IntArray:
    """The best local optimum of the fit half from each start and from greedy addition."""
    p = starts[0].size
    candidates = [fast_interchange(costs, weight, s) for s in starts]
    candidates.append(fast_interchange(costs, weight, greedy(costs, weight, p)))
    values = [_total(costs, weight, c) for c in candidates]
    return candidates[int(np.argmin(values))]


def _total(costs: FloatArray, weight: FloatArray, rows: IntArray) -> float:
    return float(weight @ costs[rows].min(axis=0))


def _pair(current: IntArray, chosen: IntArray) -> IntArray:
    """The chosen sites in vehicle order: a vehicle already on one keeps it, the others
    take the rest in ascending order."""
    free = sorted(set(chosen.tolist()) - set(current.tolist()))
    keep = set(chosen.tolist())
    out = [r if r in keep else -1 for r in current.tolist()]
    for k, r in enumerate(out):
        if r < 0:
            out[k] = free.pop(0)
    return np.array(out, dtype=np.int64)
