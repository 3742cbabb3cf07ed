"""A fleet that starts at the p-median of a history.

The fleet is created through the service's own optimum start (``start.optimum``
of ``POST /v1/fleets``: :mod:`routing_svc.service.creation` solves the p-median
of the sample's empirical distribution, :func:`routing_svc.sa.prior_counts` counts
the sample's targets toward each vehicle's step counter), as ``simulate
--start prior:N`` starts. The sample is the history's calls in time order,
thinned evenly to the route's limit when there are more.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

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


def history_sample(table: CallTable, placed: PlacedCalls | None) -> list[dict[str, Any]]:
    """Positions of the calls in time order, at most :data:`MAX_SAMPLE`, evenly spaced:
    the checked ``(edge, offset)`` positions, or without ``placed`` the places as the
    file gives them (the service then resolves them, and refuses a bad one)."""
    if placed is None:
        order = np.argsort(table.seconds, kind="stable").astype(np.int64)
        return [table.place(i) for i in _thinned(order)]
    return [
        {"edge": placed.edges[i], "offset": placed.offsets[i]}
        for i in _thinned(time_order(table, placed))
    ]


def history_vehicles(vehicles: int) -> list[dict[str, Any]]:
    """The vehicles of a fleet created from a history: ``vehicles`` identical ones."""
    return [{"id": f"v{i:03d}"} for i in range(vehicles)]


def history_vehicle_types(vehicles: int) -> list[str]:
    """The type of each vehicle of :func:`history_vehicles` (the API's default type)."""
    return [VehicleSpec.model_validate(v).type for v in history_vehicles(vehicles)]


def history_fleet_spec(
    table: CallTable,
    placed: PlacedCalls | None,
    *,
    fleet_id: str,
    network: str,
    vehicles: int,
    cost: str = "length",
    seed: int = 0,
) -> dict[str, Any]:
    """The ``POST /v1/fleets`` body of ``vehicles`` identical vehicles at the history's
    p-median."""
    return {
        "id": fleet_id,
        "network": network,
        "cost": cost,
        "seed": seed,
        "vehicles": history_vehicles(vehicles),
        "start": {"optimum": {"sample": history_sample(table, placed)}},
    }
