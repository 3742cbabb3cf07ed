"""Demand from buildings: a weight per building, at the building's nearest road.

The file is the buildings table of SUMO's scenario tools (as in DLR's
``sumo-scenarios`` collection): a CSV with a header naming at least the columns
``Weight`` (the building's share of the demand, a finite number ``>= 0``) and
``GenEdge`` (the id of the drivable edge nearest to it); other columns
(``TAZ``, ``Poly``, ``Area``, ``PedEdge``, ...) are ignored. A target comes
from building ``b`` with probability ``Weight_b / sum(Weight)`` and lies on
``GenEdge_b``, uniformly along it: the weights of an edge's buildings add up
and the edge's weight is spread over its length as for a weights file
(:func:`routing_svc.demand.network.from_edge_weights`).

Buildings whose edge is not in the compiled network (missing, closed to cars
or outside the largest strongly connected component) are dropped and
reported in :class:`BuildingWeights`; when none remains the file is refused.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from routing_svc.demand.weights_file import MAX_WEIGHTS_FILE_BYTES
from routing_svc.errors import InvalidInput, PayloadTooLarge

__all__ = ["BuildingWeights", "read_building_weights"]

WEIGHT_COLUMN = "Weight"
EDGE_COLUMN = "GenEdge"


@dataclass(frozen=True, slots=True)
class BuildingWeights:
    """The buildings of a file, summed per edge of the network.

    Attributes
    ----------
    edge_weights : dict[int, float]
        Summed building weight per edge index (edges with buildings only).
    buildings : int
        Buildings in the file.
    dropped_buildings : int
        Buildings whose edge is not in the network.
    dropped_edges : tuple of str
        Those edges' ids, sorted.
    dropped_weight : float
        The share of the total weight that they carried.
    """

    edge_weights: dict[int, float]
    buildings: int
    dropped_buildings: int
    dropped_edges: tuple[str, ...]
    dropped_weight: float


def read_building_weights(
    path: str | Path,
    *,
    known_edges: Mapping[str, int],
    max_bytes: int = MAX_WEIGHTS_FILE_BYTES,
) -> BuildingWeights:
    """Read a buildings CSV and sum its weights per known edge.

    Raises
    ------
    InvalidInput
        A missing file, text that is not UTF-8 CSV, no ``Weight`` or
        ``GenEdge`` column, a weight that is not a finite number ``>= 0``
        (naming the line), no building, or no building on the network.
    PayloadTooLarge
        A file larger than ``max_bytes``.
    """
    source = Path(path)
    if not source.is_file():
        raise InvalidInput(f"buildings file {source} does not exist")
    if source.stat().st_size > max_bytes:
        raise PayloadTooLarge(f"buildings file {source} is larger than {max_bytes} bytes")
    try:
        text = source.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InvalidInput(f"{source.name}: not UTF-8 text ({exc.reason})") from None
    rows = csv.DictReader(io.StringIO(text))
    columns = rows.fieldnames or []
    if WEIGHT_COLUMN not in columns or EDGE_COLUMN not in columns:
        raise InvalidInput(
            f"{source.name}: a buildings file needs the columns {WEIGHT_COLUMN!r} and "
            f"{EDGE_COLUMN!r}, found {columns!r}"
        )
    weights: dict[int, float] = {}
    dropped: dict[str, float] = {}
    buildings = dropped_buildings = 0
    total = 0.0
    for number, row in enumerate(rows, start=2):
        raw, edge_id = row.get(WEIGHT_COLUMN), (row.get(EDGE_COLUMN) or "").strip()
        try:
            weight = float(raw or "")
        except ValueError:
            raise InvalidInput(
                f"{source.name} line {number}: weight {raw!r} is not a number"
            ) from None
        if not math.isfinite(weight) or weight < 0.0:
            raise InvalidInput(
                f"{source.name} line {number}: weight must be a finite number >= 0, got {raw!r}"
            )
        buildings += 1
        total += weight
        index = known_edges.get(edge_id)
        if index is None:
            dropped_buildings += 1
            dropped[edge_id] = dropped.get(edge_id, 0.0) + weight
            continue
        weights[index] = weights.get(index, 0.0) + weight
    if buildings == 0:
        raise InvalidInput(f"{source.name}: no building listed")
    if not weights or math.fsum(weights.values()) <= 0.0:
        raise InvalidInput(
            f"{source.name}: none of its {buildings} buildings has a positive weight on an edge "
            "of the network's car component (wrong network, or every edge closed to cars)"
        )
    return BuildingWeights(
        edge_weights=weights,
        buildings=buildings,
        dropped_buildings=dropped_buildings,
        dropped_edges=tuple(sorted(dropped)),
        dropped_weight=math.fsum(dropped.values()) / total if total > 0.0 else 0.0,
    )
