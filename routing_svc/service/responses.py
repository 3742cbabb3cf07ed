"""Response models of the REST API and the error answers each kind of route declares.

The OpenAPI document is the contract (an all-checks schemathesis run holds the
live server to it): every route has a response model, and every status it can
answer is declared, errors as ``application/problem+json`` (:class:`Problem`,
RFC 9457).

Answers are open: a model lists the members the service sends and lets further
ones through (``extra="allow"``), so a member added to an answer does not need a
model change first. Validated answers are written back in the order the service
built them (:class:`Answer`), so the bytes a route sends do not depend on the
model. Numbers the service may send as integers or floats are :data:`Number`,
which keeps each as it came (a float field would turn ``0`` into ``0.0``).
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    SerializerFunctionWrapHandler,
    model_serializer,
    model_validator,
)

from routing_svc.service.problems import PROBLEM

Number = float | int
"""A JSON number, kept as it came (integer or float)."""


class Answer(BaseModel):
    """An open answer, serialised in the order of the members it was built from."""

    model_config = ConfigDict(extra="allow")
    _order: tuple[str, ...] = PrivateAttr(default=())

    @model_validator(mode="wrap")
    @classmethod
    def _remember_order(cls, data: Any, handler: Any) -> Any:
        answer = handler(data)
        if isinstance(data, dict) and isinstance(answer, Answer):
            answer._order = tuple(data)
        return answer

    @model_serializer(mode="wrap")
    def _in_built_order(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        data: dict[str, Any] = handler(self)
        if not self._order:
            return data
        ordered = {key: data[key] for key in self._order if key in data}
        return ordered | {key: value for key, value in data.items() if key not in ordered}


# -- problems -----------------------------------------------------------------


class Issue(BaseModel):
    """One invalid member of a request (``field`` is its dotted location)."""

    field: str
    message: str


class Problem(BaseModel):
    """An error answer, ``application/problem+json`` (RFC 9457).

    ``type`` is ``urn:routing-svc:problem:<slug>``. An invalid request lists its
    ``errors``; a server error carries the ``error_id`` the server logged its
    cause under; some errors add members of their own (e.g. ``limit`` and
    ``maximum`` of an XML limit).
    """

    model_config = ConfigDict(extra="allow")

    type: str = Field(examples=["urn:routing-svc:problem:unknown-fleet"])
    title: str
    status: int = Field(ge=400, le=599)
    detail: str
    instance: str | None = None
    errors: list[Issue] | None = Field(
        default=None, description="The invalid members of the request (422 on invalid input)."
    )
    error_id: str | None = Field(
        default=None, description="Server errors: the id the server logged the cause under."
    )


PROBLEM_REF = "#/components/schemas/Problem"

RETRY_AFTER = {
    "Retry-After": {
        "description": "Seconds to wait before retrying.",
        "schema": {"type": "integer", "minimum": 0},
    }
}

WHY: dict[int, str] = {
    400: "The body or a header cannot be parsed.",
    401: "A valid `X-API-Key` is needed (when the service has one).",
    404: "No such resource.",
    409: "The request conflicts with the stored state.",
    413: "The body exceeds the service's limit.",
    422: "The request is well formed but invalid (`errors` lists the members).",
    500: "An internal error (see `error_id`).",
    503: "The store cannot serve the request now, or its deadline passed; retry later.",
}


def problems(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """The OpenAPI ``responses`` entries of the problem answers ``statuses``."""
    out: dict[int | str, dict[str, Any]] = {}
    for status in statuses:
        entry: dict[str, Any] = {
            "description": WHY[status],
            "content": {PROBLEM: {"schema": {"$ref": PROBLEM_REF}}},
        }
        if status == 503:
            entry["headers"] = RETRY_AFTER
        out[status] = entry
    return out


READ = problems(500, 503)
"""What any route that reads the store can answer besides its own statuses."""
WRITE = problems(400, 401, 413, 422, 500, 503)
"""What any route with a request body can answer besides its own statuses."""
FOUND = problems(404)
"""A route on a resource that may not exist."""
CONFLICT = problems(409)
"""A route whose request may conflict with the stored state."""
INVALID = problems(422)
"""A route whose query or headers may be invalid."""


# -- positions, fleets ---------------------------------------------------------


class DescribedPosition(Answer):
    """A position on the network: ``edge``/``offset``, its ``x``/``y``, and ``lon``/``lat``
    where the network has a projection."""

    edge: str
    offset: Number
    x: Number
    y: Number
    lon: Number | None = None
    lat: Number | None = None


class VehicleAnswer(Answer):
    """A vehicle: type, speed, its reference (what learning moves), its live state and the
    number of its updates."""

    id: str
    type: str
    speed: Number
    position: DescribedPosition = Field(description="The reference (as before ``reference``).")
    reference: DescribedPosition = Field(description="Where it waits when idle.")
    status: Literal["available", "busy", "offline"]
    current: DescribedPosition = Field(description="Where it is now.")
    at_reference: bool = Field(description="Whether ``current`` follows the reference.")
    timestamp: Number | None = Field(description="Its last reported time (epoch seconds).")
    updates: int


class StandAnswer(Answer):
    """A stand of a fleet: where it is, how many vehicles it holds, whose reference is at it."""

    position: DescribedPosition
    capacity: int
    vehicles: list[str] = Field(
        description="The ids of the vehicles whose stand it is: the nearest stand with free "
        "capacity to each reference, nearest pairs first."
    )


class ConsolidationAnswer(Answer):
    """A ``consolidating`` fleet's next consolidation (``docs/learning.md``)."""

    due_at: int = Field(description="The target count at which it falls due.")
    apply_by: int = Field(
        description="The target count by which it is applied when targets come faster than "
        "it is solved: at once for the epoch's first, else one period after ``due_at``."
    )


class FleetAnswer(Answer):
    """A fleet: its configuration, version, target count and vehicles."""

    id: str
    network: str
    cost: str
    objective: str | Number
    step: dict[str, Any]
    counting: str
    annealing: dict[str, Any] | None
    seed: int
    rule: str
    learning_vehicles: Literal["all", "available"]
    service_thresholds: list[Number]
    probe: Number | None
    version: int
    targets: int
    vehicles: list[VehicleAnswer]
    reference_demand: dict[str, Any] | None
    stands: list[StandAnswer] | None = Field(
        description="The stands the vehicles park at (stands at one position merged, their "
        "capacities added), each with the vehicles at it; null: vehicles park anywhere.",
    )
    consolidation: ConsolidationAnswer | None = Field(
        description="The next consolidation; null for a fleet that does not consolidate."
    )


class FleetList(Answer):
    """Every fleet."""

    items: list[FleetAnswer]


class EventAnswer(Answer):
    """One stored event: its payload and, for a target, the answer its poster got."""

    seq: int
    kind: str
    payload: dict[str, Any]
    result: dict[str, Any] | None
    created_at: str = Field(description="ISO 8601 time of the commit.")


class EventPage(Answer):
    """Events after ``after``; ``next_after`` is where the next page starts."""

    items: list[EventAnswer]
    next_after: int


class OptimumGap(Answer):
    """The expected cost now against the optimum of the reference demand."""

    kind: str
    objective: Number
    expected_cost: Number
    gap: Number | None = Field(
        description="(expected_cost - objective) / objective; 0 when both are 0, null "
        "when only the optimum is (no finite relative gap)"
    )
    method: str
    proven_optimal: bool


class LevelsOver(Answer):
    """Service levels over some targets (see ``docs/api.md``)."""

    targets: int
    undispatched: int = Field(description="Targets not dispatched in full (queued, partial).")
    within: list[Number | None] = Field(description="Fraction within each threshold.")
    percentiles: dict[str, Number | None] = Field(description="p50, p90, p95 of the completion.")
    window: int | None = None


class ServiceLevels(Answer):
    """The completion cost of the dispatched vehicles against the fleet's thresholds."""

    thresholds: list[Number]
    all: LevelsOver
    recent: LevelsOver


class FleetMetrics(Answer):
    """Targets applied, mean costs, step sizes, update counts and the gap to the optimum."""

    version: int
    targets: int
    mean_cost: Number | None
    recent_mean_cost: Number | None
    recent_window: int | None
    step_size: dict[str, Number]
    updates: dict[str, int]
    optimum: OptimumGap | None
    service_levels: ServiceLevels


# -- targets ------------------------------------------------------------------


class SentVehicle(Answer):
    """A vehicle sent to a target."""

    vehicle: str
    type: str = Field(description="The required type it fills ('*': any one vehicle).")
    cost: Number = Field(description="Its travel time D / v from its current position.")


class DispatchAnswer(Answer):
    """Who goes now: per required type the closest available vehicles by current position."""

    status: Literal["dispatched", "partial", "queued"]
    vehicles: list[SentVehicle]
    missing: list[str] = Field(description="One entry per required vehicle nobody fills.")
    cost: Number | None = Field(description="The completion: the last one's arrival.")


class Assignment(Answer):
    """Who would serve a target (nothing changes)."""

    version: int
    target: DescribedPosition
    requires: list[str] | None
    dispatch: DispatchAnswer
    served_by: list[str]
    times: list[Number]
    moved: str | None
    cost: Number
    objective: Number


class PostAnswer(Answer):
    """Where one available vehicle should wait now."""

    vehicle: str
    position: DescribedPosition
    reference_of: str = Field(description="The vehicle whose reference the post is.")
    time: Number = Field(description="Travel time from the vehicle's current position.")


class Posts(Answer):
    """Where the available vehicles should wait while others are busy (nothing changes)."""

    version: int
    posts: list[PostAnswer]


class BackedOff(Answer):
    """A vehicle moved back by the probe rule, and where to."""

    position: DescribedPosition
    vehicle: str


class TargetResult(Answer):
    """A served target: who served it, who moved, by how much and where to."""

    consolidated: dict[str, Any] | None = Field(
        default=None,
        description="Present when the target started a consolidation: its `positions` "
        "are the new references of the vehicles it moved, all of the fleet's in id order, "
        "or, for a fleet that learns per type, those of `vehicles` (one type the target "
        "needed).",
    )
    backed_off: list[BackedOff]
    cost: Number
    dispatch: DispatchAnswer | None = Field(
        default=None, description="Who was sent (absent only in results stored before it)."
    )
    moved: str
    moved_by: Number
    new_position: DescribedPosition
    noise: Number
    objective: Number
    requires: list[str] | None
    seq: int
    served_by: list[str]
    step_size: Number
    target: DescribedPosition
    times: list[Number]
    version: int


class TargetBatchResult(Answer):
    """The results of a batch, in order, and the fleet's version after it."""

    version: int
    results: list[TargetResult]


class VehicleStateResult(Answer):
    """The ``vehicle_state`` event: the changed vehicles as they are now."""

    seq: int
    version: int
    vehicles: list[VehicleAnswer]


class TravelTimesResult(Answer):
    """The event that recorded new travel times."""

    seq: int
    version: int
    edges: int


# -- networks, health ---------------------------------------------------------


class NetworkAnswer(Answer):
    """A network's counts and bounds."""

    id: str
    name: str
    junctions: int = Field(description="Junctions of the compiled network.")
    edges: int = Field(
        description="Edges of the compiled network: the largest strongly connected part of "
        "the usable edges, where every edge reaches every other."
    )
    usable_edges: int = Field(
        description="Non-internal edges of the file open to the vehicle class (``vclass``)."
    )
    dropped_edges: int = Field(
        description="``usable_edges - edges``: usable edges outside the largest strongly "
        "connected part, left out of the compiled network."
    )
    bounds: list[Number] = Field(
        min_length=4, max_length=4, description="``[xmin, ymin, xmax, ymax]`` in metres."
    )
    has_projection: bool = Field(description="Whether positions may be given as lon/lat.")
    sha256: str = Field(description="SHA-256 of the network file as read.")
    vclass: str


class UnresolvedPosition(Answer):
    """A position of the request that is not on the network, and why."""

    index: int
    detail: str


class ResolvedPositions(Answer):
    """Each position of the request on the network, in order (``null`` where it is not),
    and why the others are not."""

    positions: list[DescribedPosition | None]
    unresolved: list[UnresolvedPosition]


class NetworkList(Answer):
    """Every network."""

    items: list[NetworkAnswer]


class Geometry(Answer):
    """GeoJSON (RFC 7946) of the usable edges, in the network's own coordinates."""

    type: Literal["FeatureCollection"]
    bbox: list[Number]
    features: list[dict[str, Any]]


class Health(Answer):
    """Whether the store can take a write now (``reason`` says why not)."""

    status: Literal["ok", "unavailable"]
    database: str
    networks: int
    connections_in_use: int | None
    reason: str | None = None


# -- the document --------------------------------------------------------------


def complete_document(document: dict[str, Any]) -> dict[str, Any]:
    """FastAPI's OpenAPI ``document`` with the problem answers made whole, in place.

    Adds :class:`Problem` to the components, and declares FastAPI's own 422
    (which it documents as ``HTTPValidationError`` JSON) as the problem the
    service answers with (``problems.install_problem_handlers``). An optional
    query or header parameter is left out to mean "none": its schema does not
    offer ``null``, which a URL or a header could only carry as the text "null".
    """
    schemas = document.setdefault("components", {}).setdefault("schemas", {})
    problem = Problem.model_json_schema(ref_template="#/components/schemas/{model}")
    schemas.update(problem.pop("$defs", {}))
    schemas["Problem"] = problem
    for operations in document.get("paths", {}).values():
        for operation in operations.values():
            answers = operation.get("responses", {})
            if "HTTPValidationError" in str(answers.get("422", "")):
                answers["422"] = problems(422)[422]
            for parameter in operation.get("parameters", []):
                parameter["schema"] = _without_null(parameter["schema"])
    for name in ("HTTPValidationError", "ValidationError"):
        schemas.pop(name, None)
    return document


def _without_null(schema: dict[str, Any]) -> dict[str, Any]:
    """``schema`` without the ``null`` choice of an ``anyOf`` (its other keys kept)."""
    choices = [c for c in schema.get("anyOf", []) if c != {"type": "null"}]
    if len(choices) != 1:
        return schema
    rest = {key: value for key, value in schema.items() if key != "anyOf"}
    only: dict[str, Any] = choices[0]
    return only | rest
