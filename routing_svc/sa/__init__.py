"""The pure stochastic-approximation core: no I/O, no network imports."""

from routing_svc.sa.annealing import Annealing
from routing_svc.sa.fleet import (
    Dispatch,
    Fleet,
    FleetConfig,
    FleetState,
    Outcome,
    Vehicle,
    prior_counts,
)
from routing_svc.sa.objectives import COVERAGE, ROUTING, Objective
from routing_svc.sa.plane import EuclideanPlane
from routing_svc.sa.schedules import (
    Constant,
    Counting,
    Floor,
    InverseScaling,
    Schedule,
    default_probe,
    default_schedule,
    schedule_from_dict,
)
from routing_svc.sa.space import Assignment, Requirement, Space

__all__ = [
    "COVERAGE",
    "ROUTING",
    "Annealing",
    "Assignment",
    "Constant",
    "Counting",
    "Dispatch",
    "EuclideanPlane",
    "Fleet",
    "FleetConfig",
    "FleetState",
    "Floor",
    "InverseScaling",
    "Objective",
    "Outcome",
    "Requirement",
    "Schedule",
    "Space",
    "Vehicle",
    "default_probe",
    "default_schedule",
    "prior_counts",
    "schedule_from_dict",
]
