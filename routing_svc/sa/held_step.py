"""The paper's step, held until it is worth a jump: the update rule of the ``consolidating`` fleet.

On a directed road network the expected cost ``J`` of a fleet jumps where a
reference leaves a junction (the demand it reached through the junction's other
turns now needs a detour around the block) or passes a target (which it now
reaches only by a loop). The step of eq. (10), a move ``gamma_k`` along the
path to the target, sees only the smooth part of ``J``, so even an
infinitesimal step pays the whole jump; a fleet started at the optimum (whose
references sit at junctions and demand points) is driven away from it.

The held step keeps eq. (10) and changes only when it is applied. A reference
accumulates the steps of the targets it serves as a *pressure* toward the
direction they leave by (the first junction on their path): a step in the
direction held adds to it, a step in another direction takes from it (a
majority vote of the targets it serves, weighted by ``gamma_k``). When the
pressure reaches the window ``h`` the reference moves ``min(pressure, D)``
along the path, never past that junction. A reference therefore moves only for
a net majority of its demand in one direction, by at least ``h`` or onto the
junction, which is what makes a jump worth paying; the junctions and demand
points where the p-median lies are fixed points.
"""

from __future__ import annotations

import math
from typing import Generic, NamedTuple, Protocol, runtime_checkable

from routing_svc.errors import InvalidInput
from routing_svc.sa.space import P


class Hold(NamedTuple, Generic[P]):
    """A reference held on a junction: the exit it leans to and the pressure toward it.

    ``exit`` is the first junction beyond the exit (:meth:`JunctionSpace.junction_ahead`).
    """

    exit: P
    pressure: float


@runtime_checkable
class JunctionSpace(Protocol[P]):
    """A space with junctions, where a reference gives up turns when it leaves one."""

    def junction_ahead(self, position: P, route: object) -> tuple[P, float] | None:
        """The first junction strictly ahead of ``position`` along ``route`` and its cost;
        ``None`` when the route ends before one."""
        ...

    def advance(self, position: P, target: P, route: object, amount: float) -> P:
        """Move ``position`` a cost ``amount`` along ``route`` toward ``target``."""
        ...


def held_step(
    space: JunctionSpace[P],
    position: P,
    target: P,
    route: object,
    *,
    amount: float,
    path_cost: float,
    hold: Hold[P] | None,
    window: float,
) -> tuple[P, float, Hold[P] | None]:
    """One held step of the mover; returns its new position, the cost moved and its hold.

    Parameters
    ----------
    space : JunctionSpace
        The road network.
    position, target, route
        The mover's reference, the target and the path :meth:`Space.assign` found.
    amount : float
        The step of eq. (10) (``gamma_k`` for the routing objective, see
        :meth:`routing_svc.sa.objectives.Objective.step_amount`).
    path_cost : float
        ``D``, the cost of the path to the target.
    hold : Hold or None
        The mover's hold, ``None`` when it has none.
    window : float
        ``h``: the pressure that takes a reference off a junction.
    """
    if not (math.isfinite(amount) and amount >= 0.0 and math.isfinite(window) and window > 0.0):
        raise InvalidInput("a held step needs a finite amount >= 0 and a window > 0")
    ahead = space.junction_ahead(position, route)
    if ahead is None:  # on the end of the target's edge: nowhere to go
        return position, 0.0, hold
    exit_ = ahead[0]
    if hold is not None and hold.exit == exit_:
        pressure = hold.pressure + amount
    elif hold is not None and hold.pressure > amount:
        return position, 0.0, Hold(hold.exit, hold.pressure - amount)
    else:
        pressure = amount - (hold.pressure if hold is not None else 0.0)
    if pressure < window:
        return position, 0.0, Hold(exit_, pressure)
    new, moved = _move(space, position, target, route, min(pressure, path_cost), ahead)
    return new, moved, None


def _move(
    space: JunctionSpace[P],
    position: P,
    target: P,
    route: object,
    amount: float,
    ahead: tuple[P, float],
) -> tuple[P, float]:
    """Move ``amount`` along the route, stopping on the junction ahead; and the cost moved."""
    if amount >= ahead[1]:
        return ahead[0], ahead[1]
    if amount <= 0.0:
        return position, 0.0
    return space.advance(position, target, route, amount), amount
