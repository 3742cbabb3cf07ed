"""Optional annealing noise (the remark in section II of the paper).

Adding a small decaying random perturbation to each move lets the iterates
leave poor local minima of the non-convex deployment objective. The noise of
the ``k``-th target has magnitude ``|N(0, 1)| * scale / (k + 1)**decay`` in cost
units and a random direction chosen by the space. Its random numbers come
from ``numpy.random.default_rng([seed, k])``, so a replay of the same targets
reproduces it bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from routing_svc.errors import InvalidInput


@dataclass(frozen=True, slots=True)
class Annealing:
    """Decaying noise added to each move.

    Parameters
    ----------
    scale : float
        Noise magnitude at ``k = 0``, in cost units.
    decay : float
        ``scale / (k + 1)**decay``; larger than the step's power so that the
        noise vanishes faster than the steps.
    """

    scale: float
    decay: float = 1.0

    def __post_init__(self) -> None:
        for name, value in (("scale", self.scale), ("decay", self.decay)):
            if not math.isfinite(value) or value <= 0.0:
                raise InvalidInput(f"annealing {name} must be a finite number > 0, got {value!r}")

    def amount(self, *, seed: int, k: int) -> tuple[float, np.random.Generator]:
        """The noise magnitude for target ``k`` and the generator for its direction."""
        rng = np.random.default_rng([seed, k])
        sigma = self.scale / (k + 1) ** self.decay
        return abs(float(rng.standard_normal())) * sigma, rng

    def to_dict(self) -> dict[str, Any]:
        return {"scale": self.scale, "decay": self.decay}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Annealing:
        if not isinstance(data, dict) or "scale" not in data:
            raise InvalidInput("annealing needs 'scale' (and optionally 'decay')")
        return cls(float(data["scale"]), float(data.get("decay", 1.0)))
