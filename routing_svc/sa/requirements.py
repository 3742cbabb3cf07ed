"""Turning a target's required vehicle types into search groups.

A target requires a multiset of vehicle types: ``["A", "B"]`` (the paper's
``ab`` target, section IV-C), ``["A", "A"]`` (two A vehicles) or nothing
(any one vehicle of the fleet). The search finds, for each required type, the
closest vehicles of that type; the target is served when the last of them
arrives.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

from routing_svc.errors import InvalidInput, UnmetRequirement
from routing_svc.sa.space import Requirement


def build_requirement(
    vehicle_types: Sequence[str], requires: Sequence[str] | None
) -> tuple[Requirement, tuple[str, ...]]:
    """Group the fleet's vehicles for one target.

    Parameters
    ----------
    vehicle_types : sequence of str
        The type of every vehicle, in vehicle order.
    requires : sequence of str or None
        The multiset of required types; ``None`` or empty means any one vehicle.

    Returns
    -------
    (Requirement, tuple of str)
        The search groups, and the type name of each group (``"*"`` for any).

    Raises
    ------
    UnmetRequirement
        A required type that the fleet lacks, or more of a type than it has.
    """
    n = len(vehicle_types)
    if not requires:
        if n == 0:
            raise UnmetRequirement("the fleet has no vehicles")
        return Requirement(np.zeros(n, dtype=np.int64), np.ones(1, dtype=np.int64)), ("*",)
    for name in requires:
        if not isinstance(name, str) or not name:
            raise InvalidInput(f"required types must be non-empty strings, got {name!r}")
    wanted = Counter(requires)
    available = Counter(vehicle_types)
    names = tuple(sorted(wanted))
    for name in names:
        if available[name] < wanted[name]:
            have = available[name]
            raise UnmetRequirement(
                f"target requires {wanted[name]} vehicle(s) of type {name!r}; the fleet has {have}"
            )
    code = {name: g for g, name in enumerate(names)}
    groups = np.fromiter((code.get(t, -1) for t in vehicle_types), dtype=np.int64, count=n)
    counts = np.array([wanted[name] for name in names], dtype=np.int64)
    return Requirement(groups, counts), names
