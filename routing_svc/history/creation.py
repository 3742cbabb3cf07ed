"""A fleet that starts at the p-median of a history.

The fleet is created through the service's own optimum start (``start.optimum``
of ``POST /v1/fleets``: :mod:`routing_svc.service.creation` solves the p-median
of the sample's empirical distribution, :func:`routing_svc.sa.prior_counts` counts
the sample's targets toward each vehicle's step counter), as ``simulate
--start prior:N`` starts. The sample is the history's calls in time order,
thinned evenly to the route's limit when there are more.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from routing_svc.errors import InvalidInput
from routing_svc.history.calls import CallTable
from routing_svc.history.places import PlacedCalls
from routing_svc.history.replay import time_order
from routing_svc.service.schemas import OptimumStart, VehicleSpec

MAX_SAMPLE: int = next(
    m.max_length for m in OptimumStart.model_fields["sample"].metadata if hasattr(m, "max_length")
)
"""The optimum start's limit on sample positions."""


def _thinned(order: npt.NDArray[np.int64]) -> list[int]:
    if order.shape[0] > MAX_SAMPLE:
        order = order[np.linspace(0, order.shape[0] - 1, MAX_SAMPLE).round().astype(np.int64)]
    return [int(i) for i in order.tolist()]


def history_sample(
    table: CallTable, placed: PlacedCalls | None
) -> tuple[list[dict[str, Any]], list[list[str] | None] | None]:
    """Positions of the calls in time order, at most :data:`MAX_SAMPLE`, evenly spaced:
    the checked ``(edge, offset)`` positions, or without ``placed`` the places as the
    file gives them (the service then resolves them, and refuses a bad one); and the
    types each of them needed (``None`` for any one vehicle), ``None`` when no call
    names types."""
    if placed is None:
        rows = _thinned(np.argsort(table.seconds, kind="stable").astype(np.int64))
        positions = [table.place(i) for i in rows]
    else:
        kept = _thinned(time_order(table, placed))
        positions = [{"edge": placed.edges[i], "offset": placed.offsets[i]} for i in kept]
        rows = [int(placed.rows[i]) for i in kept]
    needs = [table.requires[r] for r in rows]
    if all(n is None for n in needs):
        return positions, None
    return positions, [None if n is None else list(n) for n in needs]


VehicleMix = int | Mapping[str, int]
"""A fleet's vehicles: how many identical ones, or how many of each type."""


def parse_vehicle_mix(text: str) -> VehicleMix:
    """``"8"``: eight identical vehicles; ``"A:5,B:3"``: five of type A, three of type B.

    Raises
    ------
    InvalidInput
        Anything else, a count below 1, or a type named twice.
    """
    text = text.strip()
    if ":" not in text:
        try:
            count = int(text)
        except ValueError:
            raise InvalidInput(f"--vehicles: a count or TYPE:COUNT,..., got {text!r}") from None
        if count < 1:
            raise InvalidInput("--vehicles must be >= 1")
        return count
    mix: dict[str, int] = {}
    for part in text.split(","):
        kind, _, number = part.strip().rpartition(":")
        try:
            count = int(number)
        except ValueError:
            raise InvalidInput(f"--vehicles: {part!r} is not TYPE:COUNT") from None
        if not kind or count < 1 or kind in mix:
            raise InvalidInput(f"--vehicles: {part!r} needs a type named once and a count >= 1")
        mix[kind] = count
    return mix


def history_vehicles(vehicles: VehicleMix) -> list[dict[str, Any]]:
    """The vehicles of a fleet created from a history: ``vehicles`` identical ones, or so
    many of each type (ids in the mix's order)."""
    if isinstance(vehicles, int):
        return [{"id": f"v{i:03d}"} for i in range(vehicles)]
    kinds = [kind for kind, count in vehicles.items() for _ in range(count)]
    return [{"id": f"v{i:03d}", "type": kind} for i, kind in enumerate(kinds)]


def history_vehicle_types(vehicles: VehicleMix) -> list[str]:
    """The type of each vehicle of :func:`history_vehicles` (the API's default type for
    identical ones)."""
    return [VehicleSpec.model_validate(v).type for v in history_vehicles(vehicles)]


def history_fleet_spec(
    table: CallTable,
    placed: PlacedCalls | None,
    *,
    fleet_id: str,
    network: str,
    vehicles: VehicleMix,
    cost: str = "length",
    seed: int = 0,
) -> dict[str, Any]:
    """The ``POST /v1/fleets`` body of a fleet at the history's optimum: ``vehicles``
    identical ones at its p-median, or of several types, each type at the optimum of the
    calls that needed it (``start.optimum.requires``: the calls' types)."""
    sample, requires = history_sample(table, placed)
    optimum: dict[str, Any] = {"sample": sample}
    if requires is not None:
        optimum["requires"] = requires
    return {
        "id": fleet_id,
        "network": network,
        "cost": cost,
        "seed": seed,
        "vehicles": history_vehicles(vehicles),
        "start": {"optimum": optimum},
    }
