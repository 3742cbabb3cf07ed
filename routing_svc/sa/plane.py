"""The Euclidean plane as a space: the paper's own setting and a test oracle.

Distances are ``|p - z|``; the path toward a target is the straight segment,
so eq. (10) moves ``p <- p - gamma (p - z)/|p - z|`` and eq. (9) moves
``p <- p - gamma (p - z)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from routing_svc.errors import InvalidInput, UnmetRequirement, Unreachable
from routing_svc.sa.space import Assignment, Requirement
from routing_svc.types import FloatArray, PlanePosition


class EuclideanPlane:
    """The plane ``R^2`` (optionally with a region that sets the cost scale).

    Parameters
    ----------
    side : float
        Side of the square region where demand lives; ``typical_cost()`` returns it.
    """

    def __init__(self, *, side: float = 1.0) -> None:
        if not math.isfinite(side) or side <= 0.0:
            raise InvalidInput("side must be finite and > 0")
        self.side = side

    def assign(
        self,
        target: PlanePosition,
        positions: list[PlanePosition],
        speeds: FloatArray,
        requirement: Requirement,
    ) -> Assignment[PlanePosition]:
        """Closest vehicles per group by ``|p_i - z| / v_i``; the last to arrive moves."""
        if not (math.isfinite(target[0]) and math.isfinite(target[1])):
            raise InvalidInput("target coordinates must be finite")
        pts = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
        dist = np.hypot(pts[:, 0] - target[0], pts[:, 1] - target[1])
        times = dist / speeds
        served: list[int] = []
        served_times: list[float] = []
        for group, count in enumerate(requirement.counts):
            members = np.flatnonzero(requirement.vehicle_groups == group)
            if members.size < count:
                raise UnmetRequirement(f"group {group} needs {count} vehicles")
            order = members[np.lexsort((members, times[members]))][:count]
            served.extend(int(i) for i in order)
            served_times.extend(float(times[i]) for i in order)
        if not served:
            raise Unreachable("no vehicle can serve the target")
        limit = requirement.mover_groups
        slots = len(served) if limit is None else int(sum(requirement.counts[:limit]))
        if slots == 0:
            return Assignment(tuple(served), tuple(served_times), -1, 0.0, 0.0, None)
        mover = max(range(slots), key=lambda j: (served_times[j], -served[j]))
        m = served[mover]
        return Assignment(
            served_by=tuple(served),
            times=tuple(served_times),
            mover=m,
            completion_time=served_times[mover],
            mover_cost=float(dist[m]),
            route=None,
        )

    def advance(
        self, position: PlanePosition, target: PlanePosition, route: object, amount: float
    ) -> PlanePosition:
        """Move ``amount`` along the segment toward ``target`` (never past it)."""
        dx = target[0] - position[0]
        dy = target[1] - position[1]
        d = math.hypot(dx, dy)
        if amount >= d:
            return PlanePosition(float(target[0]), float(target[1]))
        f = amount / d
        return PlanePosition(position[0] + f * dx, position[1] + f * dy)

    def perturb(
        self, position: PlanePosition, amount: float, rng: np.random.Generator
    ) -> PlanePosition:
        """Move ``amount`` in a uniformly random direction."""
        angle = float(rng.uniform(0.0, 2.0 * math.pi))
        return PlanePosition(
            position[0] + amount * math.cos(angle), position[1] + amount * math.sin(angle)
        )

    def typical_cost(self) -> float:
        """The side of the demand region."""
        return self.side

    def cost_matrix(self, sources: list[PlanePosition], targets: list[PlanePosition]) -> FloatArray:
        """Euclidean distances, shape ``(len(sources), len(targets))``."""
        a = np.asarray(sources, dtype=np.float64).reshape(-1, 2)
        b = np.asarray(targets, dtype=np.float64).reshape(-1, 2)
        diff = a[:, None, :] - b[None, :, :]
        return np.asarray(np.hypot(diff[..., 0], diff[..., 1]), dtype=np.float64)

    def encode(self, position: PlanePosition) -> dict[str, object]:
        return {"x": float(position[0]), "y": float(position[1])}

    def encode_many(self, positions: Sequence[PlanePosition]) -> list[dict[str, object]]:
        return [self.encode(p) for p in positions]

    def decode(self, data: dict[str, object]) -> PlanePosition:
        try:
            x, y = data["x"], data["y"]
        except (KeyError, TypeError):
            raise InvalidInput("a plane position needs 'x' and 'y'") from None
        if (
            isinstance(x, bool)
            or isinstance(y, bool)
            or not isinstance(x, int | float)
            or not isinstance(y, int | float)
        ):
            raise InvalidInput("'x' and 'y' must be numbers")
        if not (math.isfinite(x) and math.isfinite(y)):
            raise InvalidInput("'x' and 'y' must be finite")
        return PlanePosition(float(x), float(y))
