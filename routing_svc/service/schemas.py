"""Request bodies of the REST API (pydantic): strict, finite, no unknown fields."""

from __future__ import annotations

from collections.abc import Sequence
from itertools import pairwise
from typing import Annotated, Any, Literal

from pydantic import (
    AwareDatetime,
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    field_validator,
    model_validator,
)

from routing_svc.sa import DEFAULT_RULE
from routing_svc.sa.fleet import can_consolidate

Finite = Annotated[float, Field(allow_inf_nan=False)]
Identifier = Annotated[
    str, StringConstraints(min_length=1, max_length=128, pattern=r"^[A-Za-z0-9_.:\-]+$")
]
TypeName = Annotated[str, StringConstraints(min_length=1, max_length=64)]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


MAX_EDGE_ID = 256
"""The longest edge id a request may name."""


class EdgePosition(Strict):
    edge: Annotated[str, StringConstraints(min_length=1, max_length=MAX_EDGE_ID)]
    offset: Annotated[float, Field(allow_inf_nan=False, ge=0.0)] = 0.0


class StandSpec(EdgePosition):
    """A stand: a place on an edge where up to ``capacity`` vehicles may park."""

    capacity: Annotated[int, Field(strict=True, ge=1, le=1_000_000)]


class XYPosition(Strict):
    x: Finite
    y: Finite


class LonLatPosition(Strict):
    lon: Annotated[float, Field(allow_inf_nan=False, ge=-180.0, le=180.0)]
    lat: Annotated[float, Field(allow_inf_nan=False, ge=-90.0, le=90.0)]


Position = EdgePosition | XYPosition | LonLatPosition

MAX_RESOLVED_POSITIONS = 10_000
"""The most positions one ``positions:resolve`` request may carry."""


class PositionBatch(Strict):
    """Positions to resolve on a network (edge/offset, x/y or lon/lat each)."""

    positions: Annotated[list[Position], Field(min_length=1, max_length=MAX_RESOLVED_POSITIONS)]


class StepSpec(Strict):
    kind: Literal["inverse", "constant"] = "inverse"
    a: Annotated[float, Field(allow_inf_nan=False, gt=0.0)]
    power: Annotated[float, Field(allow_inf_nan=False, gt=0.5, le=1.0)] | None = None
    floor: Annotated[float, Field(allow_inf_nan=False, gt=0.0)] | None = None

    def to_dict(self) -> dict[str, Any]:
        data: dict[str, Any] = {"kind": self.kind, "a": self.a}
        if self.power is not None:
            data["power"] = self.power
        if self.floor is not None:
            data["floor"] = self.floor
        return data


class AnnealingSpec(Strict):
    scale: Annotated[float, Field(allow_inf_nan=False, gt=0.0)]
    decay: Annotated[float, Field(allow_inf_nan=False, gt=0.0)] = 1.0


class VehicleSpec(Strict):
    id: Identifier
    type: TypeName = "default"
    speed: Annotated[float, Field(allow_inf_nan=False, gt=0.0, le=1e6)] = 1.0
    position: Position | None = None


class OptimumStart(Strict):
    sample: Annotated[list[Position], Field(min_length=1, max_length=5000)]
    requires: (
        Annotated[
            list[Annotated[list[TypeName], Field(max_length=64)] | None],
            Field(
                max_length=5000,
                description="Per sample position, the types its target needed (as a "
                "target's 'requires'; null or [] for any one vehicle). A fleet whose types "
                "each start apart starts each type at the optimum of the targets that "
                "needed it and of those that needed any one vehicle, refitted with the "
                "other types fixed where targets needed several types or any one.",
            ),
        ]
        | None
    ) = None

    @model_validator(mode="after")
    def _one_requirement_per_position(self) -> OptimumStart:
        if self.requires is not None and len(self.requires) != len(self.sample):
            raise ValueError(
                f"requires needs one entry per sample position: {len(self.requires)} "
                f"for {len(self.sample)}"
            )
        return self


class StartSpec(Strict):
    optimum: OptimumStart


class RequirementShare(Strict):
    requires: Annotated[
        list[TypeName],
        Field(
            max_length=64,
            description="The multiset of vehicle types a target of this class needs "
            "(['A', 'B']: one A and one B; ['A', 'A']: two A's; []: any one vehicle).",
        ),
    ]
    share: Annotated[
        float,
        Field(
            allow_inf_nan=False,
            gt=0.0,
            le=1e9,
            description="Relative frequency of the class (the shares are normalised to sum to 1).",
        ),
    ]


class DemandSpec(Strict):
    kind: Literal["uniform", "hotspots", "weights"]
    count: Annotated[int, Field(ge=1, le=50)] = 3
    spread: Annotated[float, Field(allow_inf_nan=False, gt=0.0)] | None = None
    seed: Annotated[int, Field(ge=0, le=2**63 - 1)] = 0
    weights: dict[str, Annotated[float, Field(allow_inf_nan=False, ge=0.0)]] | None = None
    requirements: (
        Annotated[
            list[RequirementShare],
            Field(
                min_length=1,
                max_length=64,
                description="The requirement mix of the targets; default: any one vehicle. "
                "With more than one vehicle type or speed, or any required type, the "
                "optimum is the heterogeneous one (objective (11) of Le Ny & Pappas).",
            ),
        ]
        | None
    ) = None


class FleetSpec(Strict):
    id: Identifier
    network: Identifier
    cost: Literal["length", "time"] = "length"
    objective: (
        Literal["routing", "coverage"]
        | Annotated[float, Field(allow_inf_nan=False, ge=1.0, le=10.0)]
    ) = "routing"
    step: StepSpec | None = None
    counting: Literal["vehicle", "fleet"] = "vehicle"
    annealing: AnnealingSpec | None = None
    seed: Annotated[int, Field(ge=0, le=2**63 - 1)] = 0
    vehicles: Annotated[
        list[VehicleSpec],
        Field(
            min_length=1,
            max_length=10_000,
            description="The fleet's vehicles; their ids must be unique (a rule JSON Schema "
            "cannot state for objects: a repeated id is a 422).",
        ),
    ]
    start: StartSpec | None = None
    reference_demand: DemandSpec | None = None
    rule: (
        Annotated[
            Literal["consolidating", "probe", "paper"],
            Field(
                description="Learning rule: 'consolidating' (held steps of eq. (10) and "
                "consolidations of recent targets; the default when each type's vehicles "
                "share one speed, and, with several types, there are no stands: then each "
                "type consolidates on the targets that need it), 'probe' "
                "(eq. (10) with the backward probe; the default for the other fleets) or "
                "'paper' (eq. (10) alone). Without a rule, a 'probe' value or annealing "
                "chooses the probe rule (a probe of 0: the paper's), as before.",
            ),
        ]
        | None
    ) = None
    probe: (
        Annotated[
            float,
            Field(
                allow_inf_nan=False,
                ge=0.0,
                le=1.0,
                description="The probe rule's window of the backward probe that sees where "
                "the expected cost jumps on a directed network, as a fraction of the cell "
                "radius R = typical trip cost / sqrt(vehicles); default 0.05, 0 = the "
                "paper's rule alone.",
            ),
        ]
        | None
    ) = None

    learning_vehicles: Annotated[
        Literal["all", "available"],
        Field(
            description="Whose reference learns from a target: 'all' (the paper's eq. (10): "
            "the closest reference moves, busy or not) or 'available' (the closest reference "
            "among the available vehicles moves, as in the hypercube model).",
        ),
    ] = "all"
    stands: (
        Annotated[
            list[StandSpec],
            Field(
                min_length=1,
                max_length=10_000,
                description="The stands the vehicles may park at, each an edge, an offset and "
                "a capacity (`routing-svc stands FILE.add.xml --net NET --json` lists those of a "
                "SUMO additional file): a consolidation then solves over the stands only, "
                "with their capacities, and every vehicle has the nearest stand with free "
                "capacity to its reference. Every stand must be on the network, and the "
                "capacities must hold the fleet. Default: vehicles park anywhere.",
            ),
        ]
        | None
    ) = None
    service_thresholds: Annotated[
        list[Annotated[float, Field(allow_inf_nan=False, gt=0.0, le=1e9)]],
        Field(
            min_length=1,
            max_length=16,
            description="Service-level thresholds in cost units: the metrics report the "
            "fraction of targets the dispatched vehicles complete within each.",
        ),
    ] = [300.0, 600.0, 900.0]

    @field_validator("service_thresholds")
    @classmethod
    def _increasing(cls, thresholds: list[float]) -> list[float]:
        if any(b <= a for a, b in pairwise(thresholds)):
            raise ValueError("service thresholds must be strictly increasing")
        return thresholds

    def learning_rule(self) -> str:
        """The rule asked for: ``rule``; else the probe rule when a probe window or
        annealing is given (the paper's for a window of 0); else the default for a
        fleet that can consolidate (:func:`~routing_svc.sa.fleet.can_consolidate`), and
        the probe rule for the others."""
        if self.rule is not None:
            return self.rule
        if self.probe is not None:
            return "probe" if self.probe > 0.0 else "paper"
        if self.annealing is not None:
            return "probe"
        consolidates = can_consolidate(
            [v.type for v in self.vehicles],
            [v.speed for v in self.vehicles],
            stands=self.stands is not None,
        )
        return DEFAULT_RULE.value if consolidates else "probe"

    @field_validator("vehicles")
    @classmethod
    def _unique_ids(cls, vehicles: list[VehicleSpec]) -> list[VehicleSpec]:
        ids = [v.id for v in vehicles]
        if len(set(ids)) != len(ids):
            raise ValueError("vehicle ids must be unique")
        return vehicles


class TargetSpec(Strict):
    position: Position
    requires: Annotated[list[TypeName], Field(max_length=64)] | None = None


class TargetBatch(Strict):
    targets: Annotated[list[TargetSpec], Field(min_length=1, max_length=10_000)]


def edge_target(edge: str, offset: float, requires: Sequence[str] | None) -> dict[str, Any]:
    """A target ``offset`` metres along ``edge`` as a validated body holds it
    (``TargetSpec.model_dump(mode="json")``, which a request's digest is taken over)."""
    return {
        "position": {"edge": edge, "offset": float(offset)},
        "requires": list(requires) if requires is not None else None,
    }


class TravelTimes(Strict):
    times: dict[
        Annotated[str, StringConstraints(min_length=1, max_length=MAX_EDGE_ID)],
        Annotated[float, Field(allow_inf_nan=False, gt=0.0, le=1e7)],
    ]


# -- vehicle state and dispatch ---------------------------------------------------

VehicleStatus = Literal["available", "busy", "offline"]
Timestamp = Annotated[float, Field(allow_inf_nan=False, ge=0.0, le=1e11)] | AwareDatetime


class VehicleStateSpec(Strict):
    """A vehicle's new live state (``PUT /v1/fleets/{id}/vehicles/{vid}/state``)."""

    status: VehicleStatus
    position: Position | None = Field(
        None,
        description="Where the vehicle is now; left out: where it was; null: at its reference.",
    )
    timestamp: Timestamp | None = Field(
        None,
        description="When the state was observed (seconds since the epoch or ISO 8601 with "
        "a zone); may not go back before the vehicle's last timestamp.",
    )


class VehicleStateChange(VehicleStateSpec):
    """One vehicle's new state in a batch."""

    vehicle: Identifier


class VehicleStateBatch(Strict):
    """Many vehicles' new states, applied together or not at all."""

    changes: Annotated[list[VehicleStateChange], Field(min_length=1, max_length=10_000)]
