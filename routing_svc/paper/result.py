"""The record of one paper experiment: what the JSON holds and the figure draws.

An experiment is a pure function of its options and a seed; it returns an
:class:`ExperimentResult` whose fields are plain JSON values (numbers,
strings, lists, dicts). The figure is drawn from that record alone, so a
figure can always be redrawn from its JSON.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from routing_svc.json_text import finite_or_none

JsonValue = Any
"""A value made of dicts, lists, str, int, float, bool and None."""


@dataclass(frozen=True, slots=True)
class ExperimentResult:
    """Key numbers and plotted series of one experiment.

    Attributes
    ----------
    name : str
        The experiment's name (``routing-svc paper NAME``).
    title : str
        A one-line description.
    params : dict
        Every option that determines the result (seeds included).
    summary : dict
        The key numbers, the ones ``docs/paper.md`` quotes.
    series : dict
        The data the figure draws.
    """

    name: str
    title: str
    params: dict[str, JsonValue]
    summary: dict[str, JsonValue]
    series: dict[str, JsonValue] = field(default_factory=dict)

    def to_json(self) -> dict[str, JsonValue]:
        """A JSON-ready dict (non-finite floats become ``None``)."""
        return {
            "name": self.name,
            "title": self.title,
            "params": jsonable(self.params),
            "summary": jsonable(self.summary),
            "series": jsonable(self.series),
        }

    @classmethod
    def from_json(cls, data: Mapping[str, JsonValue]) -> ExperimentResult:
        """Inverse of :meth:`to_json` (up to arrays becoming lists)."""
        return cls(
            name=str(data["name"]),
            title=str(data["title"]),
            params=dict(data["params"]),
            summary=dict(data["summary"]),
            series=dict(data["series"]),
        )


def jsonable(value: JsonValue) -> JsonValue:
    """Convert numpy arrays and scalars (recursively) to JSON values.

    Floats are rounded to 6 significant digits to keep the files small and
    readable; NaN and infinities become ``None``.
    """
    if isinstance(value, Mapping):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, str | bool) or value is None:
        return value
    if isinstance(value, Sequence):
        return [jsonable(item) for item in value]
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        number = finite_or_none(float(value))
        return None if number is None else float(f"{number:.6g}")
    raise TypeError(f"not a JSON value: {value!r}")


def seed_generators(seed: int, count: int) -> list[np.random.Generator]:
    """``count`` independent generators derived from one seed (``SeedSequence.spawn``)."""
    return [np.random.default_rng(child) for child in np.random.SeedSequence(seed).spawn(count)]


def quantile_band(
    values: np.ndarray[Any, Any], *, keep: np.ndarray[Any, Any] | None = None
) -> dict[str, JsonValue]:
    """Median and the 10 % / 90 % quantiles over runs (rows) of ``values``.

    ``keep`` selects the columns to store (see :func:`thinned`).
    """
    low, median, high = np.quantile(values, [0.1, 0.5, 0.9], axis=0)
    if keep is not None:
        low, median, high = low[keep], median[keep], high[keep]
    return {"q10": low, "median": median, "q90": high}


def thinned(length: int, *, points: int = 400) -> np.ndarray[Any, np.dtype[np.int64]]:
    """About ``points`` evenly spaced indices of ``range(length)``, first and last included.

    Curves of thousands of periods are stored at this resolution: the JSON
    stays small and the figure looks the same.
    """
    return np.unique(np.linspace(0, length - 1, min(points, length)).round().astype(np.int64))
