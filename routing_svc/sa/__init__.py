"""The pure stochastic-approximation core: no I/O, no network imports."""

from routing_svc.sa.annealing import Annealing
from routing_svc.sa.consolidation import Consolidation, ConsolidationPolicy
from routing_svc.sa.fleet import (
    Dispatch,
    Fleet,
    FleetConfig,
    FleetState,
    Outcome,
    Rule,
    Vehicle,
    prior_counts,
)
from routing_svc.sa.learning import DEFAULT_RULE, learning_config
from routing_svc.sa.live import LearningVehicles, Sent, Status, VehicleState
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
    "DEFAULT_RULE",
    "ROUTING",
    "Annealing",
    "Assignment",
    "Consolidation",
    "ConsolidationPolicy",
    "Constant",
    "Counting",
    "Dispatch",
    "EuclideanPlane",
    "Fleet",
    "FleetConfig",
    "FleetState",
    "Floor",
    "InverseScaling",
    "LearningVehicles",
    "Objective",
    "Outcome",
    "Requirement",
    "Rule",
    "Schedule",
    "Sent",
    "Space",
    "Status",
    "Vehicle",
    "VehicleState",
    "default_probe",
    "default_schedule",
    "learning_config",
    "prior_counts",
    "schedule_from_dict",
]
