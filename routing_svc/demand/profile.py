"""A time-of-day profile: how the rate of requests varies over the 24 hours.

A profile file holds 24 numbers, the relative weight of hours 0-1, 1-2, ...,
23-24, separated by commas or newlines; blank lines and lines starting with
``#`` are skipped. Weights are finite, ``>= 0`` with a positive sum. The rate
at simulation time ``t`` (seconds, hour ``h = floor(t / 3600) mod 24``) is the
base rate times ``24 w_h / sum(w)``, so that a day has as many requests on
average as without a profile. Requests with such a rate are drawn by thinning
(Lewis & Shedler): a Poisson stream at the largest rate, each kept with
probability ``rate(t) / largest rate``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from routing_svc.errors import InvalidInput

__all__ = ["HOURS", "HourlyProfile", "read_profile"]

HOURS = 24
MAX_PROFILE_BYTES = 64 * 1024


@dataclass(frozen=True, slots=True)
class HourlyProfile:
    """Relative request rates of the 24 hours of a day.

    Parameters
    ----------
    weights : tuple of float
        24 finite weights ``>= 0`` with a positive sum.
    """

    weights: tuple[float, ...]

    def __post_init__(self) -> None:
        w = self.weights
        if len(w) != HOURS or not all(math.isfinite(x) and x >= 0.0 for x in w):
            raise InvalidInput(f"a profile needs {HOURS} finite weights >= 0, got {w!r}")
        if math.fsum(w) <= 0.0:
            raise InvalidInput("a profile's weights must have a positive sum")

    def factor(self, time: float) -> float:
        """The rate multiplier ``24 w_h / sum(w)`` at ``time`` seconds."""
        hour = math.floor(time / 3600.0) % HOURS
        return HOURS * self.weights[hour] / math.fsum(self.weights)

    @property
    def largest_factor(self) -> float:
        """The largest multiplier over the day."""
        return HOURS * max(self.weights) / math.fsum(self.weights)


def read_profile(path: Path) -> HourlyProfile:
    """Read a profile file (format in the module docstring).

    Raises
    ------
    InvalidInput
        A missing or oversized file, a value that is not a number, not 24 of them.
    """
    if not path.is_file():
        raise InvalidInput(f"profile file {path} does not exist")
    if path.stat().st_size > MAX_PROFILE_BYTES:
        raise InvalidInput(f"profile file {path} is larger than {MAX_PROFILE_BYTES} bytes")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InvalidInput(f"profile file {path.name} is not UTF-8 text") from None
    values: list[float] = []
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        for field in stripped.split(","):
            try:
                values.append(float(field))
            except ValueError:
                raise InvalidInput(
                    f"{path.name} line {number}: {field.strip()!r} is not a number"
                ) from None
    if len(values) != HOURS:
        raise InvalidInput(
            f"{path.name}: a profile needs {HOURS} hourly weights, got {len(values)}"
        )
    return HourlyProfile(tuple(values))
