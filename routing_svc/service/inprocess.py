"""The fleet service without HTTP: the same domain code and JSON shapes as the REST API.

The co-simulation uses it by default; ``HttpFleetClient`` is the drop-in for a
running server (``--service-url``).
"""

from __future__ import annotations

import contextlib
import json
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from routing_svc.errors import Conflict, InvalidInput
from routing_svc.service.fleets import FleetService
from routing_svc.service.networks import NetworkRegistry
from routing_svc.service.schemas import (
    FleetSpec,
    TargetSpec,
    TravelTimes,
    VehicleStateBatch,
    VehicleStateChange,
    VehicleStateSpec,
)
from routing_svc.store import EventLog


def _validated(model: Any, data: Mapping[str, Any]) -> Any:
    try:
        return model.model_validate(dict(data))
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first.get("loc", ()))
        raise InvalidInput(f"{where}: {first.get('msg')}") from None


class InProcessFleetClient:
    """A :class:`routing_svc.client.FleetClient` over an in-process :class:`FleetService`.

    Parameters
    ----------
    database_url : str, optional
        Where the event log lives; a fresh SQLite file in a temporary folder by default.
    recent_window : int
        Targets in the "recent" mean cost.
    consolidation_workers : int
        Processes that solve due consolidations off the write path, as the server's
        setting of that name (:mod:`routing_svc.service.background_solver`); 0 (the
        default) solves each inside the target that made it due, so that a run is the
        same whatever the machine's speed.
    """

    def __init__(
        self,
        *,
        database_url: str | None = None,
        recent_window: int = 200,
        consolidation_workers: int = 0,
    ) -> None:
        self._tmp = tempfile.TemporaryDirectory(prefix="routing_svc_")
        url = database_url or f"sqlite:///{Path(self._tmp.name) / 'fleet.db'}"
        self.log = EventLog(url).open()
        self.networks = NetworkRegistry(
            data_dir=Path(self._tmp.name) / "networks", max_bytes=256 * 1024 * 1024
        )
        self.service = FleetService(
            self.log,
            self.networks,
            recent_window=recent_window,
            consolidation_workers=consolidation_workers,
        )

    def close(self) -> None:
        self.service.close()
        self.log.close()
        self._tmp.cleanup()

    def __enter__(self) -> InProcessFleetClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def add_network(self, path: Path, *, name: str | None = None) -> dict[str, Any]:
        entry = self.networks.load(name or Path(path).name.split(".")[0], Path(path), name=name)
        with contextlib.suppress(Conflict):
            self.log.create_network(
                entry.id, sha256=entry.network.source_sha256, path=str(path), name=entry.name
            )
        return entry.summary()

    def create_fleet(self, spec: Mapping[str, Any]) -> dict[str, Any]:
        return self.service.create_fleet(_validated(FleetSpec, spec))

    def get_fleet(self, fleet_id: str) -> dict[str, Any]:
        return self.service.get_fleet(fleet_id)

    def delete_fleet(self, fleet_id: str) -> None:
        self.service.delete_fleet(fleet_id)

    def post_target(
        self,
        fleet_id: str,
        position: Mapping[str, Any],
        *,
        requires: Sequence[str] | None = None,
        idempotency_key: str | None = None,
    ) -> dict[str, Any]:
        body = {"position": dict(position), "requires": list(requires) if requires else None}
        target = _validated(TargetSpec, body)
        results, _ = self.service.post_targets(
            fleet_id,
            [target],
            idempotency_key=idempotency_key,
            body=target.model_dump(mode="json"),
        )
        data: dict[str, Any] = json.loads(results[0])
        return data

    def assign(
        self,
        fleet_id: str,
        position: Mapping[str, Any],
        *,
        requires: Sequence[str] | None = None,
    ) -> dict[str, Any]:
        body = {"position": dict(position), "requires": list(requires) if requires else None}
        return self.service.assign(fleet_id, _validated(TargetSpec, body))

    def put_traveltimes(self, fleet_id: str, times: Mapping[str, float]) -> dict[str, Any]:
        body = _validated(TravelTimes, {"times": dict(times)})
        return self.service.put_travel_times(fleet_id, dict(body.times))

    def put_vehicle_state(
        self, fleet_id: str, vehicle: str, state: Mapping[str, Any]
    ) -> dict[str, Any]:
        _validated(VehicleStateSpec, state)  # the route's body: no ``vehicle`` inside
        change = _validated(VehicleStateChange, {**state, "vehicle": vehicle})
        return self.service.put_vehicle_states(fleet_id, [change])

    def put_vehicle_states(
        self, fleet_id: str, states: Sequence[Mapping[str, Any]]
    ) -> dict[str, Any]:
        batch = _validated(VehicleStateBatch, {"changes": [dict(s) for s in states]})
        return self.service.put_vehicle_states(fleet_id, batch.changes)

    def metrics(self, fleet_id: str) -> dict[str, Any]:
        return self.service.metrics(fleet_id)

    def posts(self, fleet_id: str) -> dict[str, Any]:
        return self.service.posts(fleet_id)
