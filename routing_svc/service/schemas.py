"""Request bodies of the REST API (pydantic): strict, finite, no unknown fields."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StringConstraints, field_validator

Finite = Annotated[float, Field(allow_inf_nan=False)]
Identifier = Annotated[
    str, StringConstraints(min_length=1, max_length=128, pattern=r"^[A-Za-z0-9_.:\-]+$")
]
TypeName = Annotated[str, StringConstraints(min_length=1, max_length=64)]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class EdgePosition(Strict):
    edge: Annotated[str, StringConstraints(min_length=1, max_length=256)]
    offset: Annotated[float, Field(allow_inf_nan=False, ge=0.0)] = 0.0


class XYPosition(Strict):
    x: Finite
    y: Finite


class LonLatPosition(Strict):
    lon: Annotated[float, Field(allow_inf_nan=False, ge=-180.0, le=180.0)]
    lat: Annotated[float, Field(allow_inf_nan=False, ge=-90.0, le=90.0)]


Position = EdgePosition | XYPosition | LonLatPosition


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


class StartSpec(Strict):
    optimum: OptimumStart


class DemandSpec(Strict):
    kind: Literal["uniform", "hotspots", "weights"]
    count: Annotated[int, Field(ge=1, le=50)] = 3
    spread: Annotated[float, Field(allow_inf_nan=False, gt=0.0)] | None = None
    seed: Annotated[int, Field(ge=0, le=2**63 - 1)] = 0
    weights: dict[str, Annotated[float, Field(allow_inf_nan=False, ge=0.0)]] | None = None


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
    vehicles: Annotated[list[VehicleSpec], Field(min_length=1, max_length=10_000)]
    start: StartSpec | None = None
    reference_demand: DemandSpec | None = None
    probe: (
        Annotated[
            float,
            Field(
                allow_inf_nan=False,
                ge=0.0,
                le=1.0,
                description="Window of the backward probe that sees where the expected "
                "cost jumps on a directed network, as a fraction of the cell radius "
                "R = typical trip cost / sqrt(vehicles); default 0.05, 0 = the paper's "
                "rule alone.",
            ),
        ]
        | None
    ) = None

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


class TravelTimes(Strict):
    times: dict[
        Annotated[str, StringConstraints(min_length=1, max_length=256)],
        Annotated[float, Field(allow_inf_nan=False, gt=0.0, le=1e7)],
    ]
