"""Service-cost objectives and the update rules of the paper.

For a target ``z`` served by vehicle ``i`` with path cost ``D = d(p_i, z)`` and
speed factor ``v_i``, the waiting time is ``T = D / v_i`` and the service cost
is ``c(T) = T**q`` with ``q >= 1``:

- ``q = 1``: the *routing* objective, eq. (10) of Le Ny & Pappas: the expected
  waiting time; its minimisers are (network) p-medians.
- ``q = 2``: the *coverage* objective, eq. (9): the expected squared distance;
  its stochastic gradient is online k-means (MacQueen).

The stochastic gradient of ``c(T)`` with respect to the mover's position points
along its shortest path toward the target and has norm ``q T**(q-1) / v_i``.
The constant ``q`` is absorbed into the step size ``gamma_k`` so that the two
classic rules come out exactly:

- routing, eq. (10): move ``gamma_k / v_i`` along the path (``gamma_k`` for a
  unit-speed vehicle: a unit subgradient), never past the target;
- coverage, eq. (9): move ``gamma_k * T / v_i`` (``gamma_k * D`` for a unit-speed
  vehicle, with ``gamma_k <= 1`` never past the target);
- power ``q``: move ``gamma_k * T**(q-1) / v_i``, truncated at the target.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from routing_svc.errors import InvalidInput
from routing_svc.sa.step_rule import step_amount


@dataclass(frozen=True, slots=True)
class Objective:
    """Service cost ``c(T) = T**power`` (``power >= 1``).

    Parameters
    ----------
    power : float
        1 for routing (eq. (10)), 2 for coverage (eq. (9)), any finite value >= 1.
    """

    power: float = 1.0

    def __post_init__(self) -> None:
        if not math.isfinite(self.power) or self.power < 1.0:
            raise InvalidInput(f"objective power must be a finite number >= 1, got {self.power!r}")

    @classmethod
    def parse(cls, spec: str | float | int) -> Objective:
        """Read ``"routing"``, ``"coverage"`` or a power such as ``1.5``."""
        if isinstance(spec, str):
            named = {"routing": 1.0, "coverage": 2.0}
            if spec in named:
                return cls(named[spec])
            try:
                return cls(float(spec))
            except ValueError:
                raise InvalidInput(
                    f"objective must be 'routing', 'coverage' or a power >= 1, got {spec!r}"
                ) from None
        if isinstance(spec, bool):
            raise InvalidInput("objective must be 'routing', 'coverage' or a power >= 1")
        return cls(float(spec))

    @property
    def name(self) -> str:
        """``routing``, ``coverage`` or ``power:q``."""
        if self.power == 1.0:
            return "routing"
        if self.power == 2.0:
            return "coverage"
        return f"power:{self.power!r}"

    def cost(self, waiting_time: float) -> float:
        """``c(T) = T**power``: the service cost of one target."""
        return float(waiting_time**self.power)

    def step_amount(self, *, gamma: float, path_cost: float, speed: float) -> float:
        """Cost the mover travels along its path for one update.

        Parameters
        ----------
        gamma : float
            The step size ``gamma_k``.
        path_cost : float
            ``D``, the mover's path cost to the target.
        speed : float
            The mover's speed factor ``v``.

        Returns
        -------
        float
            ``min(D, gamma * (D / v)**(power - 1) / v)``: eq. (10) for
            ``power = 1``, eq. (9) for ``power = 2``.
        """
        return step_amount(gamma, path_cost, speed, self.power)


ROUTING = Objective(1.0)
COVERAGE = Objective(2.0)


def routing_step_amount(*, gamma: float, path_cost: float, speed: float = 1.0) -> float:
    """Eq. (10): a unit subgradient step, ``min(D, gamma / v)``."""
    return ROUTING.step_amount(gamma=gamma, path_cost=path_cost, speed=speed)


def coverage_step_amount(*, gamma: float, path_cost: float, speed: float = 1.0) -> float:
    """Eq. (9): ``min(D, gamma * D / v**2)``; ``gamma * D`` for ``v = 1``, ``gamma <= 1``."""
    return COVERAGE.step_amount(gamma=gamma, path_cost=path_cost, speed=speed)
