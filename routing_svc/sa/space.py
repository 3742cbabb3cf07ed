"""The contract between the SA core and a space (the plane, a road network).

The core never computes a distance itself. A *space* answers two questions:

1. ``assign``: for a target and a fleet, which vehicles reach it first, one
   group of vehicles per required type, with their travel times, and which of
   them arrives last (the vehicle that moves, section IV-C of the paper);
2. ``advance``: move a position a given cost along the route found by
   ``assign`` toward the target.

Vehicle times are ``D / speed`` where ``D`` is the space's cost (metres, or
seconds at the reference speed) and ``speed`` is the vehicle's relative speed
factor (1.0 = the reference speed). Ties break by the lower vehicle index; the
fleet keeps vehicles sorted by id, so ties break by vehicle id.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Generic, NamedTuple, Protocol, TypeVar, runtime_checkable

import numpy as np

from routing_svc.types import FloatArray, IntArray

P = TypeVar("P")
P_co = TypeVar("P_co", covariant=True)


@dataclass(frozen=True, slots=True)
class Requirement:
    """How many vehicles of each group a target needs.

    Attributes
    ----------
    vehicle_groups : IntArray
        Group code of every vehicle (index = vehicle index); ``-1`` for a
        vehicle that belongs to no requested group.
    counts : IntArray
        ``counts[g]`` vehicles of group ``g`` are needed, for every group
        ``g`` in ``range(len(counts))``.

    A target of type ``ab`` in a fleet with types A and B has
    ``counts = [1, 1]`` and ``vehicle_groups[i] = 0`` for A vehicles, ``1``
    for B vehicles. "Any one vehicle" is ``counts = [1]`` with every vehicle
    in group 0.
    """

    vehicle_groups: IntArray
    counts: IntArray
    mover_groups: int | None = None
    """The mover is the last to arrive among the served vehicles of groups
    ``0 .. mover_groups - 1`` only (``None``: of every group; ``0``: no mover). The
    other groups are searched in the same pass but move nobody: the vehicles a
    target dispatches from their current positions (:mod:`routing_svc.sa.live`)."""


class Assignment(NamedTuple, Generic[P]):
    """What a space found for one target.

    Attributes
    ----------
    served_by : tuple[int, ...]
        Vehicle indices that serve the target, grouped by requirement group
        (group 0 first), closest first within a group.
    times : tuple[float, ...]
        Travel time ``D_i / v_i`` of each vehicle in ``served_by``.
    mover : int
        Index of the vehicle that arrives last (largest time; ties: lower index)
        among the groups of :attr:`Requirement.mover_groups`; ``-1`` when none
        (``mover_groups == 0``, and then the times and the route are empty).
    completion_time : float
        The mover's travel time: the time at which the target is served.
    mover_cost : float
        The mover's path cost ``D`` (before dividing by its speed).
    route : object
        Opaque data the space needs to move the mover along its path.
    """

    served_by: tuple[int, ...]
    times: tuple[float, ...]
    mover: int
    completion_time: float
    mover_cost: float
    route: object


class Space(Protocol[P]):
    """A metric-like space (possibly directed) that the SA core runs on."""

    def assign(
        self,
        target: P,
        positions: list[P],
        speeds: FloatArray,
        requirement: Requirement,
    ) -> Assignment[P]:
        """Find the serving vehicles for ``target``; raise ``Unreachable`` or
        ``UnmetRequirement`` when there are none. Never changes state."""
        ...

    def advance(self, position: P, target: P, route: object, amount: float) -> P:
        """Move ``position`` a cost ``amount`` (0 <= amount <= D) along ``route``
        toward ``target`` and return the new position."""
        ...

    def perturb(self, position: P, amount: float, rng: np.random.Generator) -> P:
        """Move ``position`` a cost ``amount`` in a random direction (annealing noise)."""
        ...

    def typical_cost(self) -> float:
        """A cost scale of the space: the length of a typical trip, used to
        derive default step sizes so that no tuning is needed."""
        ...

    def encode(self, position: P) -> dict[str, object]:
        """A JSON-ready form of a position that round-trips exactly."""
        ...

    def encode_many(self, positions: Sequence[P]) -> list[dict[str, object]]:
        """:meth:`encode` of each position (checked together)."""
        ...

    def decode(self, data: dict[str, object]) -> P:
        """Inverse of :meth:`encode`; raise ``InvalidInput``/``UnknownEdge`` on bad data."""
        ...


@runtime_checkable
class DirectedSpace(Protocol[P]):
    """A space whose expected cost ``J`` jumps where a reference passes a target or junction.

    On a directed road network a reference that moves forward stops reaching
    the targets it just passed, and the turns of the junction it just crossed,
    except by a loop: ``J`` jumps there. The paper's step (eq. (10), move the
    server a step ``gamma_k`` toward the target) is the gradient of the smooth
    part of ``J`` only; it never sees the jump term, so its fixed points need not
    be p-median optima. The fleet estimates the jump term by a one-sided finite
    difference from a point just behind each reference (see
    :attr:`FleetConfig.probe`); on a stretch shorter than the window that point
    is the junction behind the reference whose turns it gave up, which the
    fleet keeps per vehicle (:attr:`FleetState.entries`).
    """

    def back_probes(self, positions: list[P], window: float, entries: list[P | None]) -> list[P]:
        """Per reference, the point a cost ``window`` behind it; its entry if its edge is
        shorter."""
        ...

    def arrival_times(
        self, target: P, positions: list[P], speeds: FloatArray, cutoff: float
    ) -> FloatArray:
        """Each vehicle's travel time to ``target`` if below ``cutoff``, else ``inf``."""
        ...

    def back_off(self, position: P, probe: P, amount: float) -> P:
        """Move ``position`` a cost ``amount`` back toward ``probe``, not past it."""
        ...

    def entry(self, old: P, new: P, route: object, previous: P | None, window: float) -> P | None:
        """The junction (within about ``window``) behind a reference moved ``old`` -> ``new``.

        ``route`` is the path of the move (``None`` for a move without one),
        ``previous`` the entry of ``old``; ``None`` means unknown.
        """
        ...


class Served(NamedTuple, Generic[P]):
    """What a :class:`SingleTargetServing` did for one target (already applied; a named
    tuple, built once per target).

    Attributes
    ----------
    mover : int
        Index of the vehicle that served the target (and moved, unless the
        probe moved it back).
    completion_time : float
        Its arrival time ``T``.
    mover_cost : float
        Its path cost ``D``.
    amount : float
        Cost it travelled toward the target (0 when the probe moved it back).
    old_position, new_position : P
        Its reference before and after (``new_position`` is the target itself
        when it reached it).
    backed_off : tuple[tuple[int, P], ...]
        Vehicles the backward probe moved, in index order, with their new
        references.
    """

    mover: int
    completion_time: float
    mover_cost: float
    amount: float
    old_position: P
    new_position: P
    backed_off: tuple[tuple[int, P], ...]


class SingleTargetServing(Protocol[P]):
    """A space's compiled form of :meth:`Fleet.observe` for a target that needs any one vehicle.

    Optional: a space that offers it (``space.serving(speeds, window)``) does in
    one call what the fleet would do through :meth:`Space.assign`,
    :class:`DirectedSpace`'s probe and :meth:`Space.advance`, with bit-identical
    results.
    """

    def serve(
        self,
        target: P,
        positions: list[P],
        entries: list[P | None],
        gammas: FloatArray,
        power: float,
    ) -> Served[P] | None:
        """Serve ``target`` and update ``positions`` and ``entries`` in place.

        ``gammas[i]`` is vehicle ``i``'s step size for its next update, ``power``
        the objective's ``q`` (the step of :mod:`routing_svc.sa.step_rule`).
        ``None`` when the search reports an error: nothing changed, and the
        fleet's own path raises it.
        """
        ...

    def search(
        self, target: P, positions: list[P], entries: list[P | None]
    ) -> Assignment[P] | None:
        """:meth:`Space.assign` of ``target`` (checked) for any one vehicle at ``positions``,
        equal to it, moving nothing; ``None`` when the search reports an error."""
        ...
