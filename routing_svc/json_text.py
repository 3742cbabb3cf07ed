"""JSON text that the commands print and write: standard JSON (RFC 8259).

Python's :func:`json.dumps` writes an infinite or undefined float as ``Infinity`` or
``NaN``, which JSON does not have and many readers refuse. Here such a number (an
infinite wait of a request never served, a mean over nothing) is written ``null``.
"""

from __future__ import annotations

import json
import math
from typing import Any

__all__ = ["finite_or_none", "json_text"]


def finite_or_none(number: float) -> float | None:
    """``number`` if it is finite, else ``None`` (JSON ``null``)."""
    return number if math.isfinite(number) else None


def json_text(value: Any, **options: Any) -> str:
    """:func:`json.dumps` of ``value`` with every non-finite float written ``null``;
    ``options`` as for :func:`json.dumps`."""
    return json.dumps(_finite(value), allow_nan=False, **options)


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return finite_or_none(value)
    if isinstance(value, dict):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(item) for item in value]
    return value
