"""Vehicle state and dispatch: who goes now, apart from whose reference moves.

A vehicle's *reference* is where it waits when idle; it is what the SA learns
(eqs. (9)-(10) of Le Ny & Pappas). Its *state* is whether it is available now
and where it is. For each target two questions are answered in one search:

- **dispatch**: per required type, the closest *available* vehicles by their
  *current* positions (:class:`Sent`);
- **learning**: whose *reference* moves (:class:`LearningVehicles` chooses
  among which vehicles the closest reference is taken).

:func:`live_search` runs one search over a candidate set made of the
references (the learning groups) and the current positions of the available
vehicles (the dispatch groups, tagged by their group number); the space
chooses the mover among the learning groups only
(:attr:`~routing_svc.sa.space.Requirement.mover_groups`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Generic, NamedTuple

import numpy as np

from routing_svc.sa.space import Assignment, P, Requirement, Space
from routing_svc.types import FloatArray, IntArray


class Status(StrEnum):
    """Whether a vehicle can be dispatched now."""

    AVAILABLE = "available"
    BUSY = "busy"
    OFFLINE = "offline"


@dataclass(frozen=True, slots=True)
class VehicleState(Generic[P]):
    """A vehicle's live state: status, current position and the time it was reported.

    ``position`` ``None`` means "at its reference" (wherever the reference is
    now); ``timestamp`` is the last reported time (seconds since the epoch), if
    any, and a later report may not go back before it.
    """

    status: Status = Status.AVAILABLE
    position: P | None = None
    timestamp: float | None = None

    @property
    def is_default(self) -> bool:
        """Available at its reference, never time-stamped (the state of a new vehicle)."""
        return self.status is Status.AVAILABLE and self.position is None and self.timestamp is None


DEFAULT_STATE: VehicleState[object] = VehicleState()
"""The state of every vehicle of a new fleet."""


class LearningVehicles(StrEnum):
    """Among which vehicles the learning step takes the closest reference.

    ``all``: the paper's rule, eq. (10) of Le Ny & Pappas: the vehicle whose
    reference is closest moves, busy or not (it samples the gradient of the
    expected travel cost from the references).

    ``available``: the closest *available* vehicle by reference moves. Its step
    samples the gradient of the expected cost when busy vehicles are skipped,
    as a dispatcher does: in Larson's hypercube queueing model and in
    MEXCLP (Daskin's maximum expected covering location problem) a call goes
    to the closest *free* server, so the cell a reference serves grows into
    its busy neighbours' cells; eq. (10) restricted to the available vehicles
    is the stochastic gradient of that expected cost under the current
    availability. When no vehicle of a required type is available the step
    falls back to the closest reference of that type, busy or not (the target
    waits for a vehicle that returns to its reference).
    """

    ALL = "all"
    AVAILABLE = "available"


class Sent(NamedTuple):
    """The dispatch answer: the vehicles to send now, per required type.

    Attributes
    ----------
    vehicles, types : tuple of str
        The dispatched vehicles' ids and the required type each one fills
        (``"*"`` for a target that needs any one vehicle), grouped by type.
    times : tuple of float
        Each one's travel time ``D / v`` from its current position.
    missing : tuple of str
        One entry per required vehicle that no available vehicle fills.
    """

    vehicles: tuple[str, ...]
    types: tuple[str, ...]
    times: tuple[float, ...]
    missing: tuple[str, ...] = ()

    @property
    def status(self) -> str:
        """``dispatched`` (all required vehicles sent), ``partial`` or ``queued`` (none)."""
        if not self.missing:
            return "dispatched"
        return "partial" if self.vehicles else "queued"

    @property
    def completion(self) -> float | None:
        """When the last required vehicle arrives; ``None`` unless all were sent."""
        return max(self.times) if self.times and not self.missing else None

    def to_dict(self) -> dict[str, object]:
        """The answer as the API shows it."""
        return {
            "status": self.status,
            "vehicles": [
                {"vehicle": v, "type": t, "cost": c}
                for v, t, c in zip(self.vehicles, self.types, self.times, strict=True)
            ],
            "missing": list(self.missing),
            "cost": self.completion,
        }


@dataclass(frozen=True, slots=True)
class LiveAnswer(Generic[P]):
    """What :func:`live_search` found: the learning answer and the dispatch answer."""

    learning: Assignment[P]
    """Indices are vehicle indices; ``served_by`` the closest references per group."""
    sent: Sent


def live_search(
    space: Space[P],
    target: P,
    *,
    references: list[P],
    speeds: FloatArray,
    vehicle_ids: Sequence[str],
    requirement: Requirement,
    names: Sequence[str],
    states: Sequence[VehicleState[P]],
    learning_vehicles: LearningVehicles,
) -> LiveAnswer[P]:
    """Answer dispatch and learning for ``target`` with one search of ``space``.

    Parameters
    ----------
    requirement, names
        The target's groups over the vehicles and each group's type name
        (:func:`~routing_svc.sa.requirements.build_requirement`).
    states
        Every vehicle's :class:`VehicleState`, in vehicle order.
    learning_vehicles
        The learning rule's candidates (:class:`LearningVehicles`).

    Returns
    -------
    LiveAnswer
        The learning assignment (closest references; its mover moves) and the
        vehicles sent (closest available current positions).
    """
    n = len(references)
    groups = requirement.vehicle_groups
    counts = requirement.counts
    n_groups = counts.shape[0]
    available = np.fromiter((s.status is Status.AVAILABLE for s in states), dtype=bool, count=n)
    learn_groups = groups.copy()
    if learning_vehicles is LearningVehicles.AVAILABLE:
        for g in range(n_groups):
            members = groups == g
            if int(np.count_nonzero(members & available)) >= counts[g]:
                learn_groups[members & ~available] = -1
    send_counts: list[int] = []
    send_names: list[str] = []
    missing: list[str] = []
    send_group = np.full(n, -1, dtype=np.int64)
    for g in range(n_groups):
        members = (groups == g) & available
        have = min(int(counts[g]), int(np.count_nonzero(members)))
        missing.extend([names[g]] * (int(counts[g]) - have))
        if have:
            send_group[members] = n_groups + len(send_counts)
            send_counts.append(have)
            send_names.extend([names[g]] * have)
    senders = np.flatnonzero(send_group >= 0)
    candidates = list(references)
    for i in senders.tolist():
        now = states[i].position
        candidates.append(references[i] if now is None else now)
    combined = Requirement(
        np.concatenate((learn_groups, send_group[senders])),
        np.concatenate((counts, np.array(send_counts, dtype=np.int64))),
        mover_groups=n_groups,
    )
    found = space.assign(target, candidates, np.concatenate((speeds, speeds[senders])), combined)
    split = int(counts.sum())
    learning: Assignment[P] = Assignment(
        found.served_by[:split],
        found.times[:split],
        found.mover,
        found.completion_time,
        found.mover_cost,
        found.route,
    )
    sent_index = [int(senders[c - n]) for c in found.served_by[split:]]
    return LiveAnswer(
        learning,
        Sent(
            tuple(vehicle_ids[i] for i in sent_index),
            tuple(send_names),
            tuple(found.times[split:]),
            tuple(missing),
        ),
    )


def sent_from(
    learning: Assignment[P], vehicle_ids: Sequence[str], names: Sequence[str], counts: IntArray
) -> Sent:
    """The dispatch answer when every vehicle is available at its reference: the
    learning answer's vehicles themselves."""
    types = tuple(names[g] for g in range(counts.shape[0]) for _ in range(int(counts[g])))
    return Sent(tuple(vehicle_ids[i] for i in learning.served_by), types, learning.times)
