"""Reading a history of calls (a CAD export) from CSV.

The header decides what each column means (names are case-insensitive, other
columns are ignored):

``time``
    ISO 8601 (``2024-03-01T08:15:00``, with or without an offset) or a number of
    seconds. An ISO time counts from the Unix epoch (a time without an offset is
    read as UTC) and its hour of day is the one written; a number of seconds counts
    from a midnight, so its hour of day is ``floor(t / 3600) mod 24``.
a place, in exactly one of three forms
    ``lon,lat`` (WGS84 degrees), ``x,y`` (the network's coordinates, metres) or
    ``edge,offset`` (a SUMO edge id and the metres along it; ``offset`` may be
    left out, meaning 0).
``types`` or ``requires`` (optional)
    The multiset of vehicle types the call needs, as the API's targets take it
    (``TargetSpec.requires``): names joined by ``+`` or spaces (``A+B``, ``A A``)
    or a JSON list (``["A", "B"]``); empty means any one vehicle.

A row that cannot be read is a :class:`BadRow` with its line number (the header
is line 1); whether the place is on the map is checked later, against the
network (:mod:`routing_svc.history.places`).
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt

from routing_svc.errors import InvalidInput

PlaceForm = Literal["lonlat", "xy", "edge"]

PLACE_COLUMNS: dict[PlaceForm, tuple[str, str]] = {
    "lonlat": ("lon", "lat"),
    "xy": ("x", "y"),
    "edge": ("edge", "offset"),
}
REQUIRES_COLUMNS = ("types", "requires")
MAX_TYPE_NAME = 64
"""Longest vehicle type name (as ``TargetSpec`` takes it)."""
MAX_REQUIRED = 64
"""Most required types of one call (as ``TargetSpec`` takes it)."""


@dataclass(frozen=True)
class BadRow:
    """A row that is not imported: its line in the file and why."""

    line: int
    reason: str

    def to_dict(self) -> dict[str, object]:
        return {"line": self.line, "reason": self.reason}


@dataclass
class CallTable:
    """The readable rows of a history, column by column, in file order.

    Attributes
    ----------
    form
        The place form the header chose.
    lines
        Each row's line number in the file.
    seconds, hours
        Each call's time in seconds and its hour of day (0-23).
    first, second
        ``lon, lat`` or ``x, y``; for ``edge`` places ``second`` holds the offsets.
    edges
        The edge ids of ``edge`` places (empty otherwise).
    requires
        Each call's required types (``None``: any one vehicle).
    bad
        The rows that could not be read.
    sha256
        Digest of the file's bytes.
    """

    form: PlaceForm
    lines: npt.NDArray[np.int64]
    seconds: npt.NDArray[np.float64]
    hours: npt.NDArray[np.int64]
    first: npt.NDArray[np.float64]
    second: npt.NDArray[np.float64]
    edges: list[str]
    requires: list[tuple[str, ...] | None]
    sha256: str
    bad: list[BadRow] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.lines.shape[0])

    def place(self, row: int) -> dict[str, object]:
        """Row ``row``'s place as the API's position object."""
        if self.form == "edge":
            return {"edge": self.edges[row], "offset": float(self.second[row])}
        a, b = PLACE_COLUMNS[self.form]
        return {a: float(self.first[row]), b: float(self.second[row])}


def parse_time(text: str) -> tuple[float, int]:
    """``(seconds, hour of day)`` of a ``time`` cell (see the module's docstring)."""
    value = text.strip()
    try:
        seconds = float(value)
    except ValueError:
        try:
            moment = datetime.fromisoformat(value)
        except ValueError:
            raise InvalidInput(f"time {value!r} is neither ISO 8601 nor a number") from None
        stamp = moment if moment.tzinfo is not None else moment.replace(tzinfo=UTC)
        return stamp.timestamp(), moment.hour
    if not math.isfinite(seconds):
        raise InvalidInput(f"time {value!r} is not a finite number")
    return seconds, math.floor(seconds / 3600.0) % 24


def parse_requires(text: str) -> tuple[str, ...] | None:
    """The required types of a ``types`` cell (``None`` when empty)."""
    value = text.strip()
    if not value:
        return None
    if value.startswith("["):
        try:
            names = json.loads(value)
        except ValueError:
            raise InvalidInput(f"types {value!r} is not a JSON list") from None
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise InvalidInput(f"types {value!r} must be a list of type names")
    else:
        names = value.replace("+", " ").split()
    if len(names) > MAX_REQUIRED:
        raise InvalidInput(f"at most {MAX_REQUIRED} required types, got {len(names)}")
    if any(not 1 <= len(n) <= MAX_TYPE_NAME for n in names):
        raise InvalidInput(f"type names must have 1 to {MAX_TYPE_NAME} characters")
    return tuple(names) or None


def _place_form(header: list[str]) -> PlaceForm:
    forms = [
        f for f, (a, b) in PLACE_COLUMNS.items() if a in header and (b in header or f == "edge")
    ]
    if len(forms) != 1:
        given = " and ".join("/".join(PLACE_COLUMNS[f]) for f in forms) or "none"
        raise InvalidInput(
            "the header must give a place in exactly one form: lon,lat or x,y or "
            f"edge[,offset] (found {given})"
        )
    return forms[0]


def _number(text: str, name: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InvalidInput(f"{name} {text.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise InvalidInput(f"{name} {text.strip()!r} is not finite")
    return value


def read_calls(path: Path) -> CallTable:
    """Read a history file.

    Raises
    ------
    InvalidInput
        The file is missing, empty, not UTF-8 CSV, or its header has no ``time``
        column or not exactly one place form.
    """
    try:
        data = Path(path).read_bytes()
        text = data.decode("utf-8-sig")
    except OSError as exc:
        raise InvalidInput(f"cannot read {str(path)!r}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise InvalidInput(f"{str(path)!r} is not UTF-8 text") from None
    reader = csv.reader(text.splitlines())
    try:
        header = [h.strip().lower() for h in next(reader)]
    except StopIteration:
        raise InvalidInput(f"{str(path)!r} is empty") from None
    except csv.Error as exc:
        raise InvalidInput(f"{str(path)!r}: {exc}") from None
    if "time" not in header:
        raise InvalidInput("the header has no 'time' column")
    form = _place_form(header)
    a_name, b_name = PLACE_COLUMNS[form]
    t_col, a_col = header.index("time"), header.index(a_name)
    b_col = header.index(b_name) if b_name in header else None
    r_col = next((header.index(c) for c in REQUIRES_COLUMNS if c in header), None)
    width = len(header)
    lines: list[int] = []
    seconds: list[float] = []
    hours: list[int] = []
    first: list[float] = []
    second: list[float] = []
    edges: list[str] = []
    requires: list[tuple[str, ...] | None] = []
    bad: list[BadRow] = []
    line = 1
    while True:
        try:
            row = next(reader)
        except StopIteration:
            break
        except csv.Error as exc:
            bad.append(BadRow(reader.line_num, f"not CSV: {exc}"))
            continue
        line = reader.line_num
        if not row or (len(row) == 1 and not row[0].strip()):
            continue
        try:
            if len(row) != width:
                raise InvalidInput(f"{len(row)} fields, the header has {width}")
            t, hour = parse_time(row[t_col])
            if form == "edge":
                edge = row[a_col].strip()
                if not edge:
                    raise InvalidInput("empty edge id")
                offset = (
                    0.0
                    if b_col is None or not row[b_col].strip()
                    else _number(row[b_col], "offset")
                )
                if offset < 0.0:
                    raise InvalidInput(f"offset {offset} is negative")
                a, b = math.nan, offset
            else:
                a, b = _number(row[a_col], a_name), _number(row[b_col], b_name)  # type: ignore[index]
                if form == "lonlat" and not (-180.0 <= a <= 180.0 and -90.0 <= b <= 90.0):
                    raise InvalidInput(f"lon/lat ({a}, {b}) is outside [-180, 180] x [-90, 90]")
            needs = None if r_col is None else parse_requires(row[r_col])
        except InvalidInput as exc:
            bad.append(BadRow(line, exc.detail))
            continue
        lines.append(line)
        seconds.append(t)
        hours.append(hour)
        first.append(a)
        second.append(b)
        if form == "edge":
            edges.append(edge)
        requires.append(needs)
    return CallTable(
        form=form,
        lines=np.asarray(lines, dtype=np.int64),
        seconds=np.asarray(seconds, dtype=np.float64),
        hours=np.asarray(hours, dtype=np.int64),
        first=np.asarray(first, dtype=np.float64),
        second=np.asarray(second, dtype=np.float64),
        edges=edges,
        requires=requires,
        sha256=hashlib.sha256(data).hexdigest(),
        bad=bad,
    )
