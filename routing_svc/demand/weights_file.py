"""Read per-edge demand weights from a CSV or JSON file.

Two formats, told apart by the first non-blank character (``{`` means JSON):

- CSV: one ``edge_id,weight`` pair per line. Blank lines and lines starting
  with ``#`` are skipped; the first data line may be a header (``edge,weight``:
  its weight is not a number and its first column is not an edge id).
- JSON: an object ``{"edge_id": weight, ...}``.

Weights are finite numbers ``>= 0`` with a positive sum; an edge may appear
once. Every problem raises :class:`~routing_svc.errors.InvalidInput` with a
message naming the file and the line (CSV) or the key (JSON).
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping
from pathlib import Path

from routing_svc.errors import InvalidInput, PayloadTooLarge

#: Largest weights file read, in bytes.
MAX_WEIGHTS_FILE_BYTES = 64 * 1024 * 1024


def read_edge_weights(
    path: str | Path,
    *,
    known_edges: Mapping[str, int],
    max_bytes: int = MAX_WEIGHTS_FILE_BYTES,
) -> dict[int, float]:
    """Parse a weights file into ``{edge index: weight}``.

    Parameters
    ----------
    path : str or Path
        The CSV or JSON file.
    known_edges : Mapping[str, int]
        SUMO edge id -> edge index of the compiled network.
    max_bytes : int
        Files larger than this are refused.

    Returns
    -------
    dict[int, float]
        Weight of every listed edge (zeros included).

    Raises
    ------
    InvalidInput
        Missing or unreadable file, bad syntax, an unknown or duplicate edge,
        a weight that is not a finite number ``>= 0``, or no positive weight.
    PayloadTooLarge
        A file larger than ``max_bytes``.
    """
    source = Path(path)
    if not source.is_file():
        raise InvalidInput(f"demand weights file {source} does not exist")
    size = source.stat().st_size
    if size > max_bytes:
        raise PayloadTooLarge(f"demand weights file {source} has {size} bytes (limit {max_bytes})")
    try:
        text = source.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InvalidInput(f"{source}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    if text.lstrip().startswith("{"):
        weights = _parse_json(text, source.name, known_edges)
    else:
        weights = _parse_csv(text, source.name, known_edges)
    if not weights or math.fsum(weights.values()) <= 0.0:
        raise InvalidInput(f"{source.name}: no edge has a positive weight")
    if not math.isfinite(math.fsum(weights.values())):
        raise InvalidInput(f"{source.name}: the weights sum to infinity")
    return weights


def _parse_csv(text: str, name: str, known: Mapping[str, int]) -> dict[int, float]:
    weights: dict[int, float] = {}
    seen_data = False
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        where = f"{name} line {number}"
        fields = [f.strip() for f in next(csv.reader([stripped]))]
        if len(fields) != 2:
            raise InvalidInput(f"{where}: expected 'edge_id,weight', got {len(fields)} columns")
        edge_id, raw = fields
        if not seen_data and not _looks_numeric(raw) and edge_id not in known:
            seen_data = True  # a header line such as ``edge,weight``
            continue
        seen_data = True
        try:
            value = float(raw)
        except ValueError:
            raise InvalidInput(f"{where}: weight {raw!r} is not a number") from None
        _store(weights, edge_id, value, where=where, known=known)
    return weights


def _parse_json(text: str, name: str, known: Mapping[str, int]) -> dict[int, float]:
    try:
        pairs = json.loads(text, object_pairs_hook=list, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise InvalidInput(f"{name} line {exc.lineno}: malformed JSON ({exc.msg})") from None
    except ValueError as exc:
        raise InvalidInput(f"{name}: {exc}") from None
    if not isinstance(pairs, list) or not all(isinstance(p, tuple) for p in pairs):
        raise InvalidInput(f"{name}: expected a JSON object {{edge_id: weight}}")
    weights: dict[int, float] = {}
    for edge_id, value in pairs:
        where = f"{name} key {edge_id!r}"
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InvalidInput(f"{where}: weight must be a number, got {value!r}")
        _store(weights, edge_id, float(value), where=where, known=known)
    return weights


def _store(
    weights: dict[int, float], edge_id: str, value: float, *, where: str, known: Mapping[str, int]
) -> None:
    """Validate one ``(edge id, weight)`` and add it to ``weights``."""
    if edge_id.startswith(":"):
        raise InvalidInput(f"{where}: {edge_id!r} is an internal junction edge, not a road")
    index = known.get(edge_id)
    if index is None:
        raise InvalidInput(
            f"{where}: unknown edge {edge_id!r} (not in the compiled network: missing, "
            "closed to the vehicle class, or outside its largest strongly connected part)"
        )
    if not math.isfinite(value) or value < 0.0:
        raise InvalidInput(f"{where}: weight must be a finite number >= 0, got {value!r}")
    if index in weights:
        raise InvalidInput(f"{where}: edge {edge_id!r} is listed twice")
    weights[index] = value


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _reject_constant(token: str) -> float:
    raise ValueError(f"{token} is not a valid weight")
