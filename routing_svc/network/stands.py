"""Stands: the places where a fleet's vehicles may park, and which of them a network can use.

A stand is a place on an edge with a capacity (how many vehicles may wait
there). Stands come from a SUMO additional file, whose ``parkingArea``
elements become stands:

- ``lane`` gives the edge (the lane id without its ``_<index>`` suffix);
- the offset is the middle of ``startPos`` and ``endPos`` (SUMO's defaults: 0
  and the lane's length; a negative position counts from the lane's end;
  with ``friendlyPos`` a position off the lane is moved onto it);
- the capacity is ``roadsideCapacity`` plus one per ``<space>`` child.

or from a list of positions (edge, offset, capacity). A stand on an edge that
the compiled network does not have (not open to the network's vehicle class,
or outside its largest strongly connected component), off its edge, or without
capacity is dropped and reported with the reason.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import sumolib

from routing_svc.errors import InvalidInput, InvalidNetwork
from routing_svc.network.compile import CompiledNetwork
from routing_svc.network.safe_xml import check_xml_file
from routing_svc.sa.stands import StandSet
from routing_svc.types import NetPosition

__all__ = [
    "DroppedStand",
    "Stand",
    "StandReading",
    "read_stands_file",
    "stands_on_network",
    "usable_stands",
]


@dataclass(frozen=True, slots=True)
class Stand:
    """A place where vehicles may park: ``offset`` metres along SUMO edge ``edge``."""

    id: str
    edge: str
    offset: float
    capacity: int

    def to_dict(self) -> dict[str, Any]:
        """The stand as a fleet spec takes it (``{"edge", "offset", "capacity"}``)."""
        return {"edge": self.edge, "offset": self.offset, "capacity": self.capacity}


@dataclass(frozen=True, slots=True)
class DroppedStand:
    """A stand the network cannot use, and why."""

    id: str
    edge: str
    reason: str


@dataclass(frozen=True, slots=True)
class StandReading:
    """The usable stands of a source (in its order) and the dropped ones."""

    usable: tuple[Stand, ...]
    dropped: tuple[DroppedStand, ...]

    def positions(self, network: CompiledNetwork) -> list[NetPosition]:
        """The usable stands as positions of ``network``."""
        return [NetPosition(network.edge_index[s.edge], s.offset) for s in self.usable]

    @property
    def capacity(self) -> int:
        """The usable stands' total capacity."""
        return sum(s.capacity for s in self.usable)

    def stand_set(self, network: CompiledNetwork) -> StandSet[NetPosition]:
        """The usable stands as a :class:`~routing_svc.sa.stands.StandSet` of ``network``;
        stands at one position add their capacities (:meth:`StandSet.merged`).

        Raises
        ------
        InvalidInput
            No stand is usable.
        """
        positions = self.positions(network)
        return StandSet.merged(
            [(p, s.capacity) for p, s in zip(positions, self.usable, strict=True)]
        )


def stands_on_network(stands: Iterable[Stand], network: CompiledNetwork) -> StandReading:
    """Split ``stands`` into those ``network`` can use and the dropped ones.

    A stand is usable when its edge is an edge of the compiled network, its
    offset a finite number from 0 to the edge's length, and its capacity an
    integer >= 1.
    """
    usable: list[Stand] = []
    dropped: list[DroppedStand] = []
    for stand in stands:
        reason = _unusable(stand, network)
        if reason is None:
            usable.append(stand)
        else:
            dropped.append(DroppedStand(stand.id, stand.edge, reason))
    return StandReading(tuple(usable), tuple(dropped))


def read_stands_file(path: Path, network: CompiledNetwork) -> StandReading:
    """The stands of a SUMO additional file's ``parkingArea`` elements on ``network``.

    The file passes the same XML screen as any file read from outside (size,
    no DOCTYPE or entities, bounded nesting; root ``<additional>``) before
    sumolib parses it.

    Raises
    ------
    InvalidInput
        There is no file at ``path``; the file is not well-formed XML, or its root
        is not ``<additional>``; a ``parkingArea`` lacks ``id`` or ``lane``, or has a
        position or capacity that is not a number.
    """
    if not Path(path).is_file():
        raise InvalidInput(f"no stands file at {path}")
    try:
        check_xml_file(Path(path), root="additional")
    except InvalidNetwork as exc:
        raise InvalidInput(f"{path} is not a SUMO additional file: {exc.detail}") from None
    areas = sumolib.xml.parse(str(path), "parkingArea")
    return stands_on_network((_from_parking_area(a, network) for a in areas), network)


def usable_stands(path: Path, network: CompiledNetwork, vehicles: int) -> StandReading:
    """The stands of ``path`` (:func:`read_stands_file`) on ``network``, holding ``vehicles``.

    Raises
    ------
    InvalidInput
        What :func:`read_stands_file` raises; no usable stand (the first dropped
        ones named); less capacity than ``vehicles``.
    """
    reading = read_stands_file(path, network)
    if not reading.usable:
        why = "; ".join(f"{d.id} (edge {d.edge}): {d.reason}" for d in reading.dropped[:3])
        raise InvalidInput(
            f"no stand of {path} is usable on this network"
            + (f" ({len(reading.dropped)} dropped: {why})" if why else "")
        )
    reading.stand_set(network).check_fleet(vehicles)
    return reading


def _from_parking_area(area: Any, network: CompiledNetwork) -> Stand:
    stand_id, lane = area.getAttributeSecure("id"), area.getAttributeSecure("lane")
    if not stand_id or not lane:
        raise InvalidInput("every parkingArea needs an 'id' and a 'lane'")
    edge = str(lane).rpartition("_")[0] or str(lane)
    try:
        spaces = len(area.getChild("space")) if area.hasChild("space") else 0
        capacity = int(area.getAttributeSecure("roadsideCapacity", "0")) + spaces
        start = float(area.getAttributeSecure("startPos", "0"))
        end_text = area.getAttributeSecure("endPos")
        end = None if end_text is None else float(end_text)
    except ValueError:
        raise InvalidInput(
            f"parkingArea {stand_id!r}: a position or capacity is not a number"
        ) from None
    index = network.edge_index.get(edge)
    if index is None:  # its length is unknown; the network check names the reason
        return Stand(str(stand_id), edge, max(start, 0.0), capacity)
    length = float(network.length[index])
    start, end = _on_lane(start, length), _on_lane(length if end is None else end, length)
    offset = (start + end) / 2.0
    if area.getAttributeSecure("friendlyPos", "false").lower() in ("true", "1", "x"):
        offset = min(max(offset, 0.0), length)
    return Stand(str(stand_id), edge, offset, capacity)


def _on_lane(position: float, length: float) -> float:
    """SUMO's reading of a stop position: a negative one counts from the lane's end."""
    return length + position if position < 0.0 else position


def _unusable(stand: Stand, network: CompiledNetwork) -> str | None:
    index = network.edge_index.get(stand.edge)
    if index is None:
        return "edge not on the network (closed to its vehicles or not strongly connected)"
    if isinstance(stand.capacity, bool) or not isinstance(stand.capacity, int):
        return "capacity is not an integer"
    if stand.capacity < 1:
        return "no capacity"
    length = float(network.length[index])
    if not (math.isfinite(stand.offset) and 0.0 <= stand.offset <= length):
        return f"offset {stand.offset} is off the edge (length {length})"
    return None
