"""The settings of each learning rule, derived from the space alone (nothing to tune).

:func:`learning_config` is the one place where a rule's defaults are chosen; the
service, ``routing-svc simulate`` and the benchmarks all build fleets through it.
Every scale comes from the cell radius ``R = typical_cost / sqrt(p)`` of
:func:`~routing_svc.sa.schedules.default_schedule`, so the same defaults hold on
every network.
"""

from __future__ import annotations

from routing_svc.errors import InvalidInput
from routing_svc.sa.annealing import Annealing
from routing_svc.sa.consolidation import ConsolidationPolicy
from routing_svc.sa.fleet import FleetConfig, Rule
from routing_svc.sa.live import LearningVehicles
from routing_svc.sa.objectives import Objective
from routing_svc.sa.schedules import (
    DEFAULT_PROBE,
    Counting,
    Schedule,
    default_probe,
    default_schedule,
)

DEFAULT_RULE = Rule.CONSOLIDATING
"""The rule of a new fleet."""

PAPER_STEP_SCALE = 0.5
"""``a / R`` of the step schedule of the paper's rule and the probe rule."""

HELD_STEP_SCALE = 0.01
"""``a / R`` of the ``consolidating`` rule's schedule: consolidations make the large
moves, the held steps (eq. (10)) only refine."""

JUNCTION_WINDOW = 0.05
"""The pressure that takes a reference off a junction, as a fraction of ``R``."""


def learning_config(
    rule: Rule | str,
    *,
    typical_cost: float,
    n_vehicles: int,
    objective: Objective,
    seed: int = 0,
    schedule: Schedule | None = None,
    counting: Counting = Counting.VEHICLE,
    annealing: Annealing | None = None,
    probe: float | None = None,
    step_scale: float | None = None,
    prior_counts: tuple[int, ...] = (),
    consolidation: ConsolidationPolicy | None = None,
    learning_vehicles: LearningVehicles | str = LearningVehicles.ALL,
) -> FleetConfig:
    """A :class:`FleetConfig` for ``rule`` with its defaults.

    Parameters
    ----------
    rule : Rule or str
        ``paper``, ``probe`` or ``consolidating``.
    typical_cost, n_vehicles : float, int
        The space's typical trip cost and the fleet size (they give ``R``).
    objective : Objective
        The service cost.
    schedule : Schedule, optional
        An explicit step schedule (else the rule's default, scaled by ``step_scale``).
    probe : float, optional
        The probe window as a fraction of ``R`` (``probe`` rule; default 0.05).
    step_scale : float, optional
        ``a / R`` of the default schedule (default: the rule's).
    consolidation : ConsolidationPolicy, optional
        When to consolidate (``consolidating`` rule; default :class:`ConsolidationPolicy`).
    learning_vehicles : LearningVehicles or str
        Among which vehicles the closest reference moves: ``all`` (the paper's) or
        ``available`` (:class:`~routing_svc.sa.live.LearningVehicles`); every rule
        takes either.
    """
    kind = Rule(rule)
    if kind is Rule.PROBE and probe == 0.0:
        kind = Rule.PAPER  # a window of 0: the paper's rule alone
        probe = None
    if kind is not Rule.PROBE and probe is not None:
        raise InvalidInput("a probe window belongs to the 'probe' rule")
    if kind is Rule.CONSOLIDATING and annealing is not None:
        raise InvalidInput("the 'consolidating' rule takes no annealing")
    if kind is not Rule.CONSOLIDATING and consolidation is not None:
        raise InvalidInput("a consolidation policy belongs to the 'consolidating' rule")
    default_scale = HELD_STEP_SCALE if kind is Rule.CONSOLIDATING else PAPER_STEP_SCALE
    if schedule is None:
        schedule = default_schedule(
            typical_cost=typical_cost,
            n_vehicles=n_vehicles,
            power=objective.power,
            scale=default_scale if step_scale is None else step_scale,
        )
    window = None
    if kind is Rule.PROBE:
        fraction = DEFAULT_PROBE if probe is None else probe
        window = default_probe(typical_cost=typical_cost, n_vehicles=n_vehicles, fraction=fraction)
    junction = None
    if kind is Rule.CONSOLIDATING:
        junction = default_probe(
            typical_cost=typical_cost, n_vehicles=n_vehicles, fraction=JUNCTION_WINDOW
        )
        consolidation = consolidation or ConsolidationPolicy()
    return FleetConfig(
        objective=objective,
        schedule=schedule,
        counting=counting,
        annealing=annealing,
        seed=seed,
        probe=window,
        prior_counts=prior_counts,
        window=junction,
        consolidation=consolidation,
        learning_vehicles=LearningVehicles(learning_vehicles),
        per_type=kind is Rule.CONSOLIDATING,
    )
