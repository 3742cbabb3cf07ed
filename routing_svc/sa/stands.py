"""Learning between stands: the places a fleet's vehicles may park, each with a capacity.

A fleet restricted to stands learns its references as any other (eq. (10) of
Le Ny & Pappas moves them freely); what it serves from are its vehicles'
*stands*. Two rules, each implemented once here:

- **A vehicle's stand** (:func:`stand_assignment`): the stand nearest to its
  reference with free capacity, "nearest" by the cost ``d(stand, reference)``
  (the trip a vehicle waiting at the stand makes to where its reference would
  have it). Pairs (stand, vehicle) are taken in ascending order of cost; a pair
  is assigned when its vehicle has no stand yet and its stand has room left, so
  each vehicle gets the nearest stand not filled by vehicles nearer to it.
- **The p-median over stands** (:func:`capacitated_sites`): the objective
  ``sum_j w_j min_{i in S} d(s_i, z_j)^q`` (eq. (11)) is a minimum over the open
  stands, so a second vehicle at an open stand lowers no atom's cost. The
  optimum with at most ``capacity`` vehicles per stand is therefore the optimum
  over ``min(p, n_stands)`` distinct stands, the other vehicles parked where
  capacity is free (:func:`fill_capacity`); it exists when the total capacity
  is at least ``p``.

The consolidation (:mod:`routing_svc.sa.consolidation`) solves over stands with
this rule, and :mod:`routing_svc.optimum.stands` gives the optimum.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Generic

import numpy as np

from routing_svc.errors import InvalidInput
from routing_svc.sa.space import P
from routing_svc.types import FloatArray, IntArray


@dataclass(frozen=True, slots=True)
class StandSet(Generic[P]):
    """The stands a fleet may park at: distinct positions, each with a capacity >= 1."""

    positions: tuple[P, ...]
    capacities: tuple[int, ...]

    def __post_init__(self) -> None:
        if not self.positions or len(self.positions) != len(self.capacities):
            raise InvalidInput("stands need at least one position, each with a capacity")
        if len(set(self.positions)) != len(self.positions):
            raise InvalidInput("stands must be at distinct positions")
        for capacity in self.capacities:
            if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 1:
                raise InvalidInput(f"a stand's capacity must be an integer >= 1, got {capacity!r}")

    @classmethod
    def merged(cls, stands: Sequence[tuple[P, int]]) -> StandSet[P]:
        """Stands in order of first appearance; stands at one position add their capacities."""
        totals: dict[P, int] = {}
        for position, capacity in stands:
            if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 1:
                raise InvalidInput(f"a stand's capacity must be an integer >= 1, got {capacity!r}")
            totals[position] = totals.get(position, 0) + capacity
        return cls(tuple(totals), tuple(totals.values()))

    @property
    def capacity(self) -> int:
        """The total capacity."""
        return sum(self.capacities)

    def check_fleet(self, vehicles: int) -> None:
        """Refuse a fleet of more vehicles than the stands hold."""
        if vehicles > self.capacity:
            raise InvalidInput(
                f"{vehicles} vehicles exceed the total capacity {self.capacity} of the stands"
            )

    def to_dict(self, encode: Callable[[P], dict[str, object]]) -> list[dict[str, Any]]:
        return [
            {**encode(p), "capacity": c}
            for p, c in zip(self.positions, self.capacities, strict=True)
        ]

    @classmethod
    def from_dict(
        cls, data: list[dict[str, Any]], decode: Callable[[dict[str, object]], P]
    ) -> StandSet[P]:
        if not isinstance(data, list):
            raise InvalidInput("stands must be a list")
        try:
            return cls(
                tuple(decode({k: v for k, v in s.items() if k != "capacity"}) for s in data),
                tuple(s["capacity"] for s in data),
            )
        except (KeyError, TypeError, AttributeError):
            raise InvalidInput("a stored stand is malformed") from None


def stand_assignment(costs: FloatArray, capacities: Sequence[int]) -> IntArray:
    """Each vehicle's stand: the nearest with free capacity, nearest pairs first.

    Parameters
    ----------
    costs : FloatArray
        ``d(stand_i, reference_k)``, shape ``(n_stands, n_vehicles)``.
    capacities : sequence of int
        Per stand; their sum is at least ``n_vehicles``.

    Returns
    -------
    IntArray
        Per vehicle, the row of its stand. Equal costs go to the lower stand, then
        the lower vehicle.
    """
    n_vehicles = costs.shape[1]
    if sum(capacities) < n_vehicles:
        raise InvalidInput("the stands hold fewer vehicles than the fleet has")
    order = np.lexsort((np.arange(costs.size) % n_vehicles, np.arange(costs.size) // n_vehicles,
                        costs.ravel()))  # fmt: skip
    free = np.array(capacities, dtype=np.int64)
    stand = np.full(n_vehicles, -1, dtype=np.int64)
    left = n_vehicles
    for flat in order.tolist():
        i, k = divmod(flat, n_vehicles)
        if stand[k] < 0 and free[i] > 0:
            stand[k], free[i], left = i, free[i] - 1, left - 1
            if left == 0:
                break
    return stand


def vehicle_stands(
    cost_matrix: Callable[[list[P], list[P]], FloatArray],
    stands: StandSet[P],
    references: Sequence[P],
) -> list[P]:
    """Each reference's stand (:func:`stand_assignment`), as a position."""
    costs = np.asarray(cost_matrix(list(stands.positions), list(references)), dtype=np.float64)
    return [stands.positions[i] for i in stand_assignment(costs, stands.capacities).tolist()]


def open_count(vehicles: int, stands: int) -> int:
    """How many distinct stands an optimum over stands opens: ``min(p, n_stands)``."""
    return min(vehicles, stands)


def fill_capacity(
    open_rows: Sequence[int], capacities: Sequence[int], vehicles: int, served: FloatArray
) -> IntArray:
    """The open stands, then one more vehicle at a time where capacity is free.

    The extra vehicles lower no cost (module docstring); they go round the stands in
    descending order of ``served`` (the demand weight each serves), one per stand and
    round, so that the busiest stands get a second vehicle first.

    Returns
    -------
    IntArray
        ``vehicles`` stand rows, ascending; each row at most its capacity times.
    """
    rows = sorted(int(r) for r in open_rows)
    if len(set(rows)) != len(rows) or len(rows) > vehicles:
        raise ValueError("the open stands must be distinct and at most one per vehicle")
    if sum(capacities) < vehicles:
        raise InvalidInput("the stands hold fewer vehicles than the fleet has")
    free = np.array(capacities, dtype=np.int64)
    free[rows] -= 1
    ranked = sorted(range(len(free)), key=lambda i: (-float(served[i]), i))
    extra: list[int] = []
    while len(rows) + len(extra) < vehicles:
        for i in ranked:
            if free[i] > 0 and len(rows) + len(extra) < vehicles:
                extra.append(i)
                free[i] -= 1
    return np.array(sorted(rows + extra), dtype=np.int64)


def capacitated_sites(
    costs: FloatArray,
    weight: FloatArray,
    capacities: Sequence[int],
    vehicles: int,
    solve: Callable[[int], IntArray],
) -> IntArray:
    """The p-median over stands with capacities: distinct stands, then the rest filled.

    Parameters
    ----------
    costs : FloatArray
        ``d(stand_i, z_j) ** q``, shape ``(n_stands, n_atoms)``.
    weight : FloatArray
        ``w_j``.
    capacities : sequence of int
        Per stand.
    vehicles : int
        ``p``.
    solve : callable
        ``solve(k)``: ``k`` distinct rows minimising ``sum_j w_j min_i costs[i, j]``
        (an exact solver or a local search).

    Returns
    -------
    IntArray
        ``p`` stand rows (ascending, repeats within capacity).
    """
    chosen = solve(open_count(vehicles, costs.shape[0]))
    owner = np.asarray(chosen)[costs[chosen].argmin(axis=0)]
    served = np.bincount(owner, weights=weight, minlength=costs.shape[0]).astype(np.float64)
    return fill_capacity(chosen.tolist(), capacities, vehicles, served)
