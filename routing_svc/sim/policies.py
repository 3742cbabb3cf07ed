"""The policies a co-simulation compares, all on identical demand.

==================  ==========================================================
``sa``              this product: the service dispatches the closest
                    available vehicle by its current position, and the
                    closest reference moves, busy or not (the paper's rule,
                    fleet option ``learning_vehicles=all``); starting at the
                    p-median of the historical requests, if any (the paper's
                    deterministic first configuration).
``sa-available``    ``sa`` with ``learning_vehicles=available``: the closest
                    reference among the available vehicles moves.
``sa-cold``         the same without history: it starts at the start
                    positions and learning starts with the run.
``sa-floor``        ``sa`` with a floored, asymptotically constant step
                    (for tracking demand that moves).
``static``          the service dispatches, reference positions frozen at the
                    start positions (``assign`` only).
``optimum``         the service dispatches, reference positions frozen at the
                    (best-known) p-median of the true demand distribution; for
                    incidents, of a large sample of incidents recorded in
                    the same traffic apart from the requests served.
``sumo-stop``       SUMO's taxi device: ``greedy`` dispatch, idle taxis stop
                    where they are.
``sumo-closest``    SUMO's taxi device: ``greedyClosest`` dispatch (the
                    reservation with the shortest travel time to pick-up
                    first), idle taxis stop where they are.
``sumo-circling``   SUMO's taxi device: ``greedy`` dispatch, idle taxis drive
                    around at random (``randomCircling``).
``sumo-taxistand``  SUMO's taxi device: ``greedy`` dispatch, idle taxis drive
                    to the closest taxi stand (``taxistand``); the stands are
                    parking areas at the ``optimum`` policy's sites, where the
                    taxis also start (with ``--stands``: the file's parking
                    areas, the taxis starting at the optimum over them).
==================  ==========================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from routing_svc.errors import InvalidInput
from routing_svc.sa import InverseScaling, default_schedule

__all__ = ["DEFAULT_POLICIES", "POLICIES", "Policy", "floored_step", "parse_policies"]


@dataclass(frozen=True, slots=True)
class Policy:
    """How the fleet is positioned and dispatched.

    Attributes
    ----------
    name : str
        The policy's name in reports.
    dispatch : {"service", "sumo"}
        ``service``: the co-simulation asks the fleet service (SUMO's taxi
        dispatch algorithm ``traci``); ``sumo``: SUMO's dispatcher ``algorithm``.
    learn : bool
        Whether each request updates the reference positions (SA).
    positions : {"start", "optimum"}
        The first reference positions.
    idle : str
        SUMO's idle algorithm (``stop`` or ``randomCircling``) for ``sumo``.
    floor : bool
        Whether the SA step has a floor (tracking).
    history : bool
        Whether the fleet starts at the p-median of the historical requests.
    learning_vehicles : {"all", "available"}
        The fleet's ``learning_vehicles`` option (whose reference learns).
    algorithm : {"greedy", "greedyClosest"}
        SUMO's taxi dispatch algorithm for ``sumo``.
    """

    name: str
    dispatch: Literal["service", "sumo"]
    learn: bool = False
    positions: Literal["start", "optimum"] = "start"
    idle: str = "stop"
    floor: bool = False
    history: bool = False
    learning_vehicles: Literal["all", "available"] = "all"
    algorithm: Literal["greedy", "greedyClosest"] = "greedy"

    @property
    def uses_stands(self) -> bool:
        """Whether the policy's vehicles wait at the stands of ``--stands``, if given
        (the service's fleets and ``sumo-taxistand``)."""
        return self.dispatch == "service" or self.idle == "taxistand"


POLICIES: dict[str, Policy] = {
    p.name: p
    for p in (
        Policy("sa", "service", learn=True, history=True),
        Policy("sa-available", "service", learn=True, history=True, learning_vehicles="available"),
        Policy("sa-cold", "service", learn=True),
        Policy("sa-floor", "service", learn=True, floor=True, history=True),
        Policy("static", "service"),
        Policy("optimum", "service", positions="optimum"),
        Policy("sumo-stop", "sumo", idle="stop"),
        Policy("sumo-closest", "sumo", idle="stop", algorithm="greedyClosest"),
        Policy("sumo-circling", "sumo", idle="randomCircling"),
        Policy("sumo-taxistand", "sumo", idle="taxistand", positions="optimum"),
    )
}
"""Every known policy by name."""

DEFAULT_POLICIES = ("sa", "sa-available", "optimum", "sumo-stop", "sumo-taxistand")

#: The floored step's minimum as a fraction of the default step's ``a``.
FLOOR_FRACTION = 0.125


def parse_policies(text: str | None) -> tuple[Policy, ...]:
    """Policies from a comma-separated list of names (``None``: the defaults)."""
    names = DEFAULT_POLICIES if not text else tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in POLICIES]
    if unknown or not names:
        raise InvalidInput(f"unknown policies {unknown}; known: {', '.join(POLICIES)}")
    return tuple(POLICIES[n] for n in dict.fromkeys(names))


def floored_step(*, typical_cost: float, vehicles: int) -> dict[str, Any]:
    """The service's default step with a floor of :data:`FLOOR_FRACTION` of its ``a``.

    The default (``routing_svc.sa.schedules.default_schedule``) is
    ``gamma_k = a / (k + 1)**0.75``; the floored one keeps
    ``gamma_k >= a / 8``, reached after about 16 updates of a vehicle, so
    that the fleet keeps following demand that moves (section III-D of the
    paper) at the price of never settling exactly.
    """
    schedule = default_schedule(typical_cost=typical_cost, n_vehicles=vehicles, power=1.0)
    if not isinstance(schedule, InverseScaling) or not math.isfinite(schedule.a):
        raise InvalidInput("the default routing schedule is expected to be InverseScaling")
    return {
        "kind": "inverse",
        "a": schedule.a,
        "power": schedule.power,
        "floor": schedule.a * FLOOR_FRACTION,
    }
