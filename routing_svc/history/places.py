"""Checking a history's places and required types before anything is sent.

Every place is resolved to an ``(edge, offset)`` position by the code the
service resolves targets with, and the position is what is sent, so the fleet
learns exactly from the checked positions:

- in process (:func:`place_locally`): the network's own
  :class:`~routing_svc.service.networks.NetworkEntry` (the same snapper, the
  same ``SNAP_DISTANCE_M``, vectorised over the whole file) and the fleet's
  vehicle types (:func:`~routing_svc.sa.requirements.build_requirement`, which
  the fleet uses for every target);
- against a server (:func:`place_remotely`): ``POST /v1/fleets/{id}/assign``
  for each distinct place and requirement, which resolves the place, checks the
  types and changes nothing; its answer gives the position;
- against a server, before the fleet exists (:func:`place_on_network`):
  ``POST /v1/networks/{id}/positions:resolve`` for the places, and the required
  types against the vehicle types the fleet will have, by the same rule as in
  process.

A row fails when its place is off the map (farther than ``SNAP_DISTANCE_M`` from
every usable edge, or an edge the network does not use, an offset past the
edge's end) or when the fleet cannot serve its required types.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from pydantic import ValidationError
from tqdm import tqdm

from routing_svc.client import FleetClient
from routing_svc.errors import InvalidInput, NotFound, OffNetwork, RoutingSvcError
from routing_svc.history.calls import BadRow, CallTable
from routing_svc.sa.requirements import build_requirement
from routing_svc.service.networks import SNAP_DISTANCE_M, NetworkEntry
from routing_svc.service.schemas import MAX_EDGE_ID, MAX_RESOLVED_POSITIONS, EdgePosition
from routing_svc.types import NetPosition

SNAP_BLOCK = 65_536
"""Points snapped per vectorised call."""


@dataclass
class PlacedCalls:
    """The rows that can be sent, with their positions, and the rows that cannot.

    ``rows`` index the :class:`CallTable`; ``edges[i], offsets[i]`` is row
    ``rows[i]``'s position; ``bad`` holds the table's unreadable rows too, by line.
    """

    rows: npt.NDArray[np.int64]
    edges: list[str]
    offsets: list[float]
    bad: list[BadRow]


Snap = Callable[..., list[NetPosition]]


def _snap_all(
    snap: Snap, a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]
) -> tuple[list[NetPosition | None], dict[int, str]]:
    """Snap every point; the points off the network are found by halving the blocks
    that fail (the snapper refuses a whole block for one such point)."""
    out: list[NetPosition | None] = [None] * a.shape[0]
    failed: dict[int, str] = {}
    stack = [(lo, min(lo + SNAP_BLOCK, a.shape[0])) for lo in range(0, a.shape[0], SNAP_BLOCK)]
    while stack:
        lo, hi = stack.pop()
        try:
            out[lo:hi] = snap(a[lo:hi], b[lo:hi], max_distance=SNAP_DISTANCE_M)
        except OffNetwork:
            if hi - lo == 1:
                failed[lo] = f"farther than {SNAP_DISTANCE_M:g} m from every usable edge"
            else:
                mid = (lo + hi) // 2
                stack += [(mid, hi), (lo, mid)]
    return out, failed


def _requirement_errors(
    requires: Sequence[tuple[str, ...] | None], vehicle_types: Sequence[str] | None
) -> dict[tuple[str, ...], str]:
    """The distinct requirements the fleet cannot serve, with the reason."""
    if vehicle_types is None:
        return {}
    errors: dict[tuple[str, ...], str] = {}
    for needs in {r for r in requires if r is not None}:
        try:
            build_requirement(vehicle_types, needs)
        except RoutingSvcError as exc:
            errors[needs] = exc.detail
    return errors


def _edge_places(
    table: CallTable, entry: NetworkEntry
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], dict[int, str]]:
    """Each edge row's edge index and offset as the route resolves them (index ``-1``:
    the row fails, for the reason given).

    The table's edge rows already have a non-empty edge id and a finite offset from 0
    (:func:`~routing_svc.history.calls.read_calls`). A row whose id is not too long, is
    a usable edge of the network, and whose offset is from 0 to the edge's length is
    what :meth:`NetworkEntry.resolve_edge` accepts, and gets its position, checked for
    all rows at once (``+ 0.0``: an offset of ``-0.0`` is the edge's start, ``0.0``).
    Every other row goes one at a time to ``resolve_edge``, or through the route's
    model when the id is too long, for its message.
    """
    network = entry.network
    lookup = network.edge_index.get
    n = len(table)
    index = np.fromiter(
        (lookup(e, -1) if len(e) <= MAX_EDGE_ID else -1 for e in table.edges),
        dtype=np.int64,
        count=n,
    )
    offsets = table.second + 0.0
    known = index >= 0
    lengths = np.where(known, network.length[np.where(known, index, 0)], -math.inf)
    accepted = known & (offsets >= 0.0) & (offsets <= lengths)
    reasons: dict[int, str] = {}
    for row in np.flatnonzero(~accepted).tolist():
        edge, offset = table.edges[row], float(table.second[row])
        try:
            if 0 < len(edge) <= MAX_EDGE_ID and 0.0 <= offset < math.inf:
                position = entry.resolve_edge(edge, offset)
            else:
                position = entry.resolve(EdgePosition(edge=edge, offset=offset))
            index[row], offsets[row] = position.edge, position.offset
        except ValidationError as exc:
            index[row] = -1
            reasons[row] = str(exc.errors()[0].get("msg"))
        except RoutingSvcError as exc:
            index[row] = -1
            reasons[row] = exc.detail
    return index, offsets, reasons


def place_locally(
    table: CallTable, entry: NetworkEntry, *, vehicle_types: Sequence[str] | None
) -> PlacedCalls:
    """Resolve every row on ``entry``; ``vehicle_types=None`` skips the type check."""
    bad = list(table.bad)
    if table.form == "edge":
        index, offsets, reasons = _edge_places(table, entry)
    else:
        if table.form == "lonlat":
            projection = entry.network.projection
            if projection is None or not projection.supported:
                raise InvalidInput(
                    f"network {entry.id!r} has no geographic projection: give x,y or edge places"
                )
            snap: Snap = entry.snapper.snap_lonlat
        else:
            snap = entry.snapper.snap_xy
        positions, reasons = _snap_all(snap, table.first, table.second)
        index = np.array([-1 if p is None else p.edge for p in positions], dtype=np.int64)
        offsets = np.array([0.0 if p is None else p.offset for p in positions], dtype=np.float64)
    unmet = _requirement_errors(table.requires, vehicle_types)
    if unmet:
        for row, needs in enumerate(table.requires):
            if needs in unmet and row not in reasons:
                reasons[row] = unmet[needs]
    placed = index >= 0
    placed[list(reasons)] = False
    for row in np.flatnonzero(~placed).tolist():
        bad.append(BadRow(int(table.lines[row]), reasons.get(row) or "no position"))
    bad.sort(key=lambda r: r.line)
    rows = np.flatnonzero(placed)
    edge_ids = entry.network.edge_ids
    edges = [edge_ids[i] for i in index[rows].tolist()]
    return PlacedCalls(rows.astype(np.int64), edges, offsets[rows].tolist(), bad)


def place_remotely(
    table: CallTable, client: FleetClient, fleet_id: str, *, progress: bool = True
) -> PlacedCalls:
    """Resolve every row with the server's ``/assign`` (once per distinct place and
    requirement); the fleet must exist (a 4xx answer then means a bad row)."""
    client.get_fleet(fleet_id)
    bad = list(table.bad)
    answers: dict[tuple[object, ...], tuple[str, float] | str] = {}
    found: list[tuple[str, float] | str] = []
    for row in tqdm(range(len(table)), disable=not progress, file=sys.stderr, unit="call"):
        place = table.place(row)
        needs = table.requires[row]
        key = (*place.values(), needs)
        if key not in answers:
            try:
                answer = client.assign(fleet_id, place, requires=needs)
                answers[key] = (str(answer["target"]["edge"]), float(answer["target"]["offset"]))
            except (InvalidInput, NotFound) as exc:  # the fleet exists: the row is bad
                answers[key] = exc.detail
        found.append(answers[key])
    return _placed(table, found, bad)


class PositionResolver(Protocol):
    """A client that resolves positions on a network of the service."""

    def resolve_positions(
        self, network_id: str, positions: list[dict[str, Any]]
    ) -> dict[str, Any]: ...


def place_on_network(
    table: CallTable,
    client: PositionResolver,
    network_id: str,
    *,
    vehicle_types: Sequence[str] | None,
    progress: bool = True,
) -> PlacedCalls:
    """Resolve every row's place with the server's ``positions:resolve`` (once per distinct
    place, :data:`MAX_RESOLVED_POSITIONS` at a time) and check its required types against
    ``vehicle_types`` as :func:`place_locally` does (``None`` skips the type check)."""
    bad = list(table.bad)
    distinct: dict[tuple[object, ...], int] = {}
    places: list[dict[str, Any]] = []
    keys: list[tuple[object, ...]] = []
    for row in range(len(table)):
        place = table.place(row)
        key = tuple(place.values())
        keys.append(key)
        if key not in distinct:
            distinct[key] = len(places)
            places.append(place)
    found: list[tuple[str, float] | str] = []
    blocks = range(0, len(places), MAX_RESOLVED_POSITIONS)
    for lo in tqdm(blocks, disable=not progress, file=sys.stderr, unit="block"):
        answer = client.resolve_positions(network_id, places[lo : lo + MAX_RESOLVED_POSITIONS])
        reasons = {int(u["index"]): str(u["detail"]) for u in answer["unresolved"]}
        for i, position in enumerate(answer["positions"]):
            if position is None:
                found.append(reasons.get(i, "not on the network"))
            else:
                found.append((str(position["edge"]), float(position["offset"])))
    unmet = _requirement_errors(table.requires, vehicle_types)
    per_row = [found[distinct[key]] for key in keys]
    checked = [
        unmet.get(needs, result) if needs is not None and not isinstance(result, str) else result
        for result, needs in zip(per_row, table.requires, strict=True)
    ]
    return _placed(table, checked, bad)


def _placed(
    table: CallTable, found: Sequence[tuple[str, float] | str], bad: list[BadRow]
) -> PlacedCalls:
    """Each row's ``(edge, offset)``, or the reason it is bad (``found[row]``), as
    :class:`PlacedCalls` with ``bad`` (the table's unreadable rows) added to."""
    rows: list[int] = []
    edges: list[str] = []
    offsets: list[float] = []
    for row, result in enumerate(found):
        if isinstance(result, str):
            bad.append(BadRow(int(table.lines[row]), result))
            continue
        rows.append(row)
        edges.append(result[0])
        offsets.append(result[1])
    bad.sort(key=lambda r: r.line)
    return PlacedCalls(np.asarray(rows, dtype=np.int64), edges, offsets, bad)
