"""A demand distribution: a finite set of weighted atoms.

The stochastic-approximation rules of Le Ny & Pappas minimise the expected
service cost ``E[min_i c(d(p_i, Z) / v_i)]`` over an *unknown* distribution of
targets ``Z``. To measure how far a fleet is from the optimum we need the true
distribution in a form where that expectation is an exact finite sum, not a
Monte Carlo estimate. A :class:`DemandDistribution` is therefore a discrete
measure: positions ``z_j`` (atoms) with weights ``w_j >= 0`` summing to one, and

.. math:: E[f(Z)] = \\sum_j w_j f(z_j).

Sampling targets from it (:meth:`DemandDistribution.sample`) gives the stream
that the online algorithm sees, so the online result and the exact optimum
refer to the same distribution.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np

from routing_svc.errors import InvalidInput
from routing_svc.types import FloatArray, NetPosition, PlanePosition

P = TypeVar("P", NetPosition, PlanePosition)

#: Largest tolerated deviation of the weight sum from one.
WEIGHT_SUM_TOLERANCE = 1e-9

_FORMAT = "routing_svc.demand/1"


@dataclass(frozen=True, eq=False)
class DemandDistribution(Generic[P]):
    """Weighted atoms ``(z_j, w_j)`` with ``sum_j w_j = 1``.

    Parameters
    ----------
    name : str
        A short description (``"uniform_by_length:20m"``, ``"hotspots:3"``, ...).
    positions : tuple of NetPosition or PlanePosition
        The atoms ``z_j``; all of one kind. A ``NetPosition`` holds an edge
        *index* of the compiled network the distribution was built on.
    weights : FloatArray
        ``w_j >= 0``, finite, summing to one within ``1e-9``. Stored as a
        read-only copy.

    Raises
    ------
    InvalidInput
        Empty distribution, mixed or unknown position kinds, a length mismatch,
        negative or non-finite weights, or weights that do not sum to one.

    See Also
    --------
    DemandDistribution.from_masses : normalise non-negative masses first.
    """

    name: str
    positions: tuple[P, ...]
    weights: FloatArray = field(repr=False)

    def __post_init__(self) -> None:
        positions = tuple(self.positions)
        weights = np.array(self.weights, dtype=np.float64, copy=True)
        if not positions:
            raise InvalidInput("a demand distribution needs at least one atom")
        if weights.shape != (len(positions),):
            raise InvalidInput(
                f"demand has {len(positions)} positions but weights of shape {weights.shape}"
            )
        kind = type(positions[0])
        if kind not in (NetPosition, PlanePosition) or any(type(p) is not kind for p in positions):
            raise InvalidInput("demand positions must all be NetPosition or all PlanePosition")
        coords = np.array([[float(p[0]), float(p[1])] for p in positions], dtype=np.float64)
        if not np.all(np.isfinite(coords)):
            raise InvalidInput("demand positions must be finite")
        if kind is NetPosition and (np.any(coords < 0.0) or np.any(coords[:, 0] % 1.0 != 0.0)):
            raise InvalidInput("network demand atoms need edge indices and offsets >= 0")
        if not np.all(np.isfinite(weights)) or np.any(weights < 0.0):
            raise InvalidInput("demand weights must be finite and >= 0")
        total = math.fsum(weights.tolist())
        if abs(total - 1.0) > WEIGHT_SUM_TOLERANCE:
            raise InvalidInput(f"demand weights must sum to 1, got {total!r}")
        weights.setflags(write=False)
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "weights", weights)

    @classmethod
    def from_masses(
        cls, name: str, positions: Sequence[P], masses: Sequence[float] | FloatArray
    ) -> DemandDistribution[P]:
        """Build a distribution from non-negative masses, dropping zero-mass atoms.

        Parameters
        ----------
        name : str
            Name of the distribution.
        positions : sequence of positions
            The atoms.
        masses : array_like
            Non-negative finite masses, one per atom, with a positive sum.

        Returns
        -------
        DemandDistribution
            Weights ``masses / sum(masses)`` on the atoms of positive mass.
        """
        mass = np.asarray(masses, dtype=np.float64)
        if mass.shape != (len(positions),):
            raise InvalidInput(f"{len(positions)} positions but masses of shape {mass.shape}")
        if not np.all(np.isfinite(mass)) or np.any(mass < 0.0):
            raise InvalidInput("demand masses must be finite and >= 0")
        keep = np.flatnonzero(mass > 0.0)
        total = float(mass[keep].sum())
        if keep.size == 0 or not math.isfinite(total) or total <= 0.0:
            raise InvalidInput("demand masses must have a positive finite sum")
        return cls(name, tuple(positions[int(i)] for i in keep), mass[keep] / total)

    @classmethod
    def of_targets(cls, name: str, targets: Sequence[P]) -> DemandDistribution[P]:
        """The empirical distribution of ``targets``: each distinct target weighted by
        how often it occurs, in the order of first occurrence.

        Raises
        ------
        InvalidInput
            No targets.
        """
        counts = Counter(targets)
        return cls.from_masses(name, list(counts), list(counts.values()))

    @property
    def kind(self) -> str:
        """``"network"`` for ``NetPosition`` atoms, ``"plane"`` for ``PlanePosition``."""
        return "network" if isinstance(self.positions[0], NetPosition) else "plane"

    def __len__(self) -> int:
        return len(self.positions)

    def sample(self, rng: np.random.Generator, n: int) -> list[P]:
        """Draw ``n`` targets independently, atom ``j`` with probability ``w_j``.

        Parameters
        ----------
        rng : numpy.random.Generator
            The source of randomness; the same seed gives the same targets.
        n : int
            Number of targets (``>= 0``).

        Returns
        -------
        list of positions
            The drawn atoms, in draw order.
        """
        if n < 0:
            raise InvalidInput(f"cannot draw a negative number of targets ({n})")
        picks = rng.choice(len(self.positions), size=n, p=self.weights)
        return [self.positions[int(j)] for j in picks]

    def to_json(self) -> str:
        """Serialise to JSON; floats round-trip exactly (``repr`` digits)."""
        atoms: list[list[float] | list[int | float]]
        if self.kind == "network":
            atoms = [[int(p[0]), float(p[1])] for p in self.positions]
        else:
            atoms = [[float(p[0]), float(p[1])] for p in self.positions]
        payload = {
            "format": _FORMAT,
            "name": self.name,
            "kind": self.kind,
            "positions": atoms,
            "weights": self.weights.tolist(),
        }
        return json.dumps(payload, allow_nan=False)

    @staticmethod
    def from_json(text: str) -> DemandDistribution[NetPosition] | DemandDistribution[PlanePosition]:
        """Inverse of :meth:`to_json`.

        Raises
        ------
        InvalidInput
            Malformed JSON, an unknown format or kind, or invalid atoms/weights.
        """
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InvalidInput(f"demand JSON is malformed: {exc}") from None
        if not isinstance(data, dict) or data.get("format") != _FORMAT:
            raise InvalidInput(f"demand JSON must be an object with format {_FORMAT!r}")
        name, kind = data.get("name"), data.get("kind")
        atoms, weights = data.get("positions"), data.get("weights")
        if not isinstance(name, str) or not isinstance(atoms, list):
            raise InvalidInput("demand JSON needs a string 'name' and a list 'positions'")
        if not isinstance(weights, list) or not all(_is_real(w) for w in weights):
            raise InvalidInput("demand JSON needs a list of numbers 'weights'")
        if not all(isinstance(a, list) and len(a) == 2 for a in atoms):
            raise InvalidInput("every demand position must be a pair")
        w = np.array(weights, dtype=np.float64)
        if kind == "network":
            if not all(_is_int(a[0]) and a[0] >= 0 and _is_real(a[1]) for a in atoms):
                raise InvalidInput("network demand positions must be [edge index >= 0, offset]")
            net = tuple(NetPosition(int(a[0]), float(a[1])) for a in atoms)
            return DemandDistribution[NetPosition](name, net, w)
        if kind == "plane":
            if not all(_is_real(a[0]) and _is_real(a[1]) for a in atoms):
                raise InvalidInput("plane demand positions must be [x, y] numbers")
            plane = tuple(PlanePosition(float(a[0]), float(a[1])) for a in atoms)
            return DemandDistribution[PlanePosition](name, plane, w)
        raise InvalidInput(f"demand kind must be 'network' or 'plane', got {kind!r}")


def _is_real(value: object) -> bool:
    """A JSON number (not a bool)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def _is_int(value: object) -> bool:
    """A JSON integer (not a bool)."""
    return isinstance(value, int) and not isinstance(value, bool)
