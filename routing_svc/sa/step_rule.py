"""The arithmetic of one SA update, written once for the reference and the compiled path.

Plain functions of floats, so that :class:`~routing_svc.sa.Fleet` calls them as
they are and :mod:`routing_svc.network.serving` compiles the very same
functions with numba (``njit(step_amount)``): the two paths cannot drift apart.
"""

from __future__ import annotations

__all__ = ["PROBE_TOLERANCE", "probe_gains", "probe_step", "step_amount"]

PROBE_TOLERANCE = 1e-9
"""A probe gains only if it beats the fleet's time by more than this fraction of it."""


def step_amount(gamma: float, path_cost: float, speed: float, power: float) -> float:
    """Cost the mover travels along its path for one update.

    ``min(D, gamma * (D / v)**(q - 1) / v)``: eq. (10) for ``q = 1`` (``gamma / v``),
    eq. (9) for ``q = 2``; ``D`` is the path cost, ``v`` the mover's speed factor.
    """
    if power == 1.0:
        return min(path_cost, gamma / speed)
    scale: float = (path_cost / speed) ** (power - 1.0)
    return min(path_cost, gamma * scale / speed)


def probe_gains(probe_time: float, completion: float) -> bool:
    """Whether a back probe that reaches the target at ``probe_time`` gains on the fleet's
    ``completion`` time by more than :data:`PROBE_TOLERANCE` of it."""
    return probe_time < completion and completion - probe_time > PROBE_TOLERANCE * completion


def probe_step(gamma: float, gain: float, window: float) -> float:
    """How far a vehicle whose probe gains ``gain`` moves back: ``min(h, gamma G / h)``,
    the backward finite difference of ``J`` over the window ``h``."""
    return min(window, gamma * gain / window)
