"""Step-size schedules ``gamma_k``.

Robbins-Monro convergence (section III of the paper) needs
``sum gamma_k = inf`` and ``sum gamma_k**2 < inf``; ``InverseScaling(a, power)``
with ``0.5 < power <= 1`` satisfies both. Tracking drifting demand
(section III-D) needs an asymptotically constant step: ``Floor`` keeps
``gamma_k >= minimum`` and ``Constant`` never decreases.

``k`` counts either every target the fleet has seen or the updates of the
vehicle that moves (``Counting``); the fleet chooses which.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Protocol

from routing_svc.errors import InvalidInput


class Counting(StrEnum):
    """What ``k`` counts in ``gamma_k``."""

    VEHICLE = "vehicle"
    """The moving vehicle's own number of past updates (MacQueen's k-means)."""
    FLEET = "fleet"
    """Every target the fleet has seen before this one."""


class StepSchedule(Protocol):
    """``gamma_k`` as a function of ``k >= 0``."""

    def __call__(self, k: int) -> float: ...

    def to_dict(self) -> dict[str, Any]: ...


def _positive(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InvalidInput(f"{name} must be a number, got {value!r}")
    if not math.isfinite(value) or value <= 0.0:
        raise InvalidInput(f"{name} must be a finite number > 0, got {value!r}")
    return float(value)


@dataclass(frozen=True, slots=True)
class Constant:
    """``gamma_k = a`` for every ``k``: tracks drift, never converges exactly."""

    a: float

    def __post_init__(self) -> None:
        _positive("step a", self.a)

    def __call__(self, k: int) -> float:
        return self.a

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "constant", "a": self.a}


@dataclass(frozen=True, slots=True)
class InverseScaling:
    """``gamma_k = a / (k + 1)**power`` with ``0.5 < power <= 1`` (Robbins-Monro)."""

    a: float
    power: float = 0.75

    def __post_init__(self) -> None:
        _positive("step a", self.a)
        _positive("step power", self.power)
        if not 0.5 < self.power <= 1.0:
            raise InvalidInput(
                f"step power must satisfy 0.5 < power <= 1 (Robbins-Monro), got {self.power!r}"
            )

    def __call__(self, k: int) -> float:
        return float(self.a / (k + 1) ** self.power)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "inverse", "a": self.a, "power": self.power}


@dataclass(frozen=True, slots=True)
class Floor:
    """``gamma_k = max(schedule(k), minimum)``: asymptotically constant, for tracking."""

    schedule: Constant | InverseScaling
    minimum: float

    def __post_init__(self) -> None:
        _positive("step minimum", self.minimum)

    def __call__(self, k: int) -> float:
        return max(self.schedule(k), self.minimum)

    def to_dict(self) -> dict[str, Any]:
        return {**self.schedule.to_dict(), "floor": self.minimum}


Schedule = Constant | InverseScaling | Floor


def schedule_from_dict(data: dict[str, Any]) -> Schedule:
    """Rebuild a schedule from :meth:`to_dict` output (or from API input).

    ``{"kind": "inverse", "a": 50.0, "power": 0.75, "floor": 1.0}`` is
    ``Floor(InverseScaling(50.0, 0.75), 1.0)``.
    """
    if not isinstance(data, dict):
        raise InvalidInput("step must be an object")
    kind = data.get("kind", "inverse")
    unknown = set(data) - {"kind", "a", "power", "floor"}
    if unknown:
        raise InvalidInput(f"unknown step fields: {sorted(unknown)}")
    if "a" not in data:
        raise InvalidInput("step needs 'a'")
    base: Constant | InverseScaling
    if kind == "constant":
        if "power" in data:
            raise InvalidInput("a constant step takes no 'power'")
        base = Constant(data["a"])
    elif kind == "inverse":
        base = InverseScaling(data["a"], data.get("power", 0.75))
    else:
        raise InvalidInput(f"step kind must be 'constant' or 'inverse', got {kind!r}")
    if data.get("floor") is not None:
        return Floor(base, data["floor"])
    return base


def default_schedule(
    *, typical_cost: float, n_vehicles: int, power: float, scale: float = 0.5
) -> Schedule:
    """A schedule that needs no tuning on any network.

    The scale comes from the space: ``typical_cost`` is the cost of a typical
    trip (for a road network, the median shortest-path cost between random
    edges; for the plane, the side of the region). ``p`` vehicles split the
    demand into cells of typical radius ``R = typical_cost / sqrt(p)``.

    - coverage (``power = 2``): ``gamma_k = 1 / (k + 1)`` per vehicle, which makes
      each reference position the running mean of its targets (MacQueen);
    - otherwise: ``gamma_k = a / (k + 1)**0.75`` with ``a = R**(2 - power) / 2``,
      (``scale`` = 1/2 by default) so that a routing vehicle (``power = 1``)
      first moves half a cell radius
      per target and the steps shrink below a percent of ``R`` within a few
      thousand updates while their sum still diverges.
    """
    if power == 2.0:
        return InverseScaling(1.0, 1.0)
    radius = typical_cost / math.sqrt(max(n_vehicles, 1))
    return InverseScaling(scale * radius ** (2.0 - power), 0.75)


DEFAULT_PROBE = 0.05
"""Default window of the backward probe, as a fraction of the cell radius ``R``."""


def default_probe(
    *, typical_cost: float, n_vehicles: int, fraction: float = DEFAULT_PROBE
) -> float:
    """The probe window ``h`` (:attr:`routing_svc.sa.FleetConfig.probe`), in cost units.

    ``h = fraction * R`` with the cell radius ``R = typical_cost / sqrt(p)`` of
    :func:`default_schedule`: the probe rule's window, and the junction window of
    the held step (:mod:`routing_svc.sa.held_step`).
    """
    if not fraction >= 0.0:
        raise InvalidInput("the probe fraction must be >= 0")
    return fraction * typical_cost / math.sqrt(max(n_vehicles, 1))
