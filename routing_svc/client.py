"""One client interface to the fleet service, in-process or over HTTP.

The co-simulation, the benchmarks and the examples talk to the service
through :class:`FleetClient`; ``HttpFleetClient`` speaks the REST API of
``docs/api.md`` and ``InProcessFleetClient`` (in
:mod:`routing_svc.service.inprocess`) calls the same domain code without
HTTP. Both return the same JSON-shaped dictionaries.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol, Self

import httpx

from routing_svc import errors


class FleetClient(Protocol):
    """What a user of the fleet service can do."""

    def add_network(self, path: Path, *, name: str | None = None) -> dict[str, Any]: ...

    def create_fleet(self, spec: Mapping[str, Any]) -> dict[str, Any]: ...

    def get_fleet(self, fleet_id: str) -> dict[str, Any]: ...

    def delete_fleet(self, fleet_id: str) -> None: ...

    def post_target(
        self,
        fleet_id: str,
        position: Mapping[str, Any],
        *,
        requires: Sequence[str] | None = None,
        idempotency_key: str | None = None,
    ) -> dict[str, Any]: ...

    def assign(
        self,
        fleet_id: str,
        position: Mapping[str, Any],
        *,
        requires: Sequence[str] | None = None,
    ) -> dict[str, Any]: ...

    def put_traveltimes(self, fleet_id: str, times: Mapping[str, float]) -> dict[str, Any]: ...

    def put_vehicle_state(
        self, fleet_id: str, vehicle: str, state: Mapping[str, Any]
    ) -> dict[str, Any]: ...

    def put_vehicle_states(
        self, fleet_id: str, states: Sequence[Mapping[str, Any]]
    ) -> dict[str, Any]: ...

    def metrics(self, fleet_id: str) -> dict[str, Any]: ...

    def posts(self, fleet_id: str) -> dict[str, Any]: ...


_STATUS_ERRORS: dict[int, type[errors.RoutingSvcError]] = {
    404: errors.NotFound,
    409: errors.Conflict,
    413: errors.PayloadTooLarge,
}


def _raise_for_problem(response: httpx.Response) -> None:
    if response.status_code < 400:
        return
    try:
        body = response.json()
        detail = str(body.get("detail") or body.get("title") or response.text)
    except ValueError:
        detail = response.text
    cls = _STATUS_ERRORS.get(response.status_code, errors.InvalidInput)
    if response.status_code >= 500:
        cls = errors.RoutingSvcError
    raise cls(f"{response.status_code}: {detail}")


class HttpFleetClient:
    """The REST API over HTTP (``httpx``), raising the domain errors on problems."""

    def __init__(self, base_url: str, *, api_key: str | None = None, timeout: float = 30.0) -> None:
        headers = {"X-API-Key": api_key} if api_key else {}
        self._base_url = base_url.rstrip("/")
        self._timeout = timeout
        self._http = httpx.Client(base_url=self._base_url, headers=headers, timeout=timeout)

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _send(
        self, method: str, path: str, *, write: bool | None = None, **request: Any
    ) -> httpx.Response:
        """One request; a transport failure becomes :class:`errors.ServiceUnreachable`.

        A write (``write``; by default any method but ``GET``) whose answer was lost
        (broken connection, timeout) may have been applied: the message says so, and a
        retry with the same idempotency key settles it."""
        where = f"{method} {self._base_url}{path}"
        try:
            return self._http.request(method, path, **request)
        except httpx.ConnectError as exc:
            raise errors.ServiceUnreachable(f"cannot connect for {where}: {exc}") from exc
        except httpx.TransportError as exc:
            lost = (
                f"no answer within {self._timeout:g} s"
                if isinstance(exc, httpx.TimeoutException)
                else f"the connection broke ({exc.__class__.__name__}: {exc})"
            )
            writes = method != "GET" if write is None else write
            maybe = "; the request may have been applied" if writes else ""
            raise errors.ServiceUnreachable(f"{where}: {lost}{maybe}") from exc

    def _json(self, response: httpx.Response) -> dict[str, Any]:
        _raise_for_problem(response)
        data: dict[str, Any] = response.json()
        return data

    def add_network(self, path: Path, *, name: str | None = None) -> dict[str, Any]:
        params = {"name": name} if name else {}
        return self._json(
            self._send("POST", "/v1/networks", params=params, content=Path(path).read_bytes())
        )

    def create_fleet(self, spec: Mapping[str, Any]) -> dict[str, Any]:
        return self._json(self._send("POST", "/v1/fleets", json=dict(spec)))

    def get_fleet(self, fleet_id: str) -> dict[str, Any]:
        return self._json(self._send("GET", f"/v1/fleets/{fleet_id}"))

    def delete_fleet(self, fleet_id: str) -> None:
        _raise_for_problem(self._send("DELETE", f"/v1/fleets/{fleet_id}"))

    def post_target(
        self,
        fleet_id: str,
        position: Mapping[str, Any],
        *,
        requires: Sequence[str] | None = None,
        idempotency_key: str | None = None,
    ) -> dict[str, Any]:
        headers = {"Idempotency-Key": idempotency_key} if idempotency_key else {}
        body = {"position": dict(position), "requires": list(requires) if requires else None}
        return self._json(
            self._send("POST", f"/v1/fleets/{fleet_id}/targets", json=body, headers=headers)
        )

    def assign(
        self,
        fleet_id: str,
        position: Mapping[str, Any],
        *,
        requires: Sequence[str] | None = None,
    ) -> dict[str, Any]:
        body = {"position": dict(position), "requires": list(requires) if requires else None}
        return self._json(
            self._send("POST", f"/v1/fleets/{fleet_id}/assign", json=body, write=False)
        )

    def put_traveltimes(self, fleet_id: str, times: Mapping[str, float]) -> dict[str, Any]:
        return self._json(
            self._send("PUT", f"/v1/fleets/{fleet_id}/traveltimes", json={"times": dict(times)})
        )

    def put_vehicle_state(
        self, fleet_id: str, vehicle: str, state: Mapping[str, Any]
    ) -> dict[str, Any]:
        """``PUT .../vehicles/{vehicle}/state`` with ``state`` (``status``, optionally
        ``position`` and ``timestamp``)."""
        return self._json(
            self._send("PUT", f"/v1/fleets/{fleet_id}/vehicles/{vehicle}/state", json=dict(state))
        )

    def put_vehicle_states(
        self, fleet_id: str, states: Sequence[Mapping[str, Any]]
    ) -> dict[str, Any]:
        """``POST .../vehicles/state:batch``: each state names its ``vehicle``; all or none."""
        body = {"changes": [dict(s) for s in states]}
        return self._json(
            self._send("POST", f"/v1/fleets/{fleet_id}/vehicles/state:batch", json=body)
        )

    def metrics(self, fleet_id: str) -> dict[str, Any]:
        return self._json(self._send("GET", f"/v1/fleets/{fleet_id}/metrics"))

    def posts(self, fleet_id: str) -> dict[str, Any]:
        """``GET .../posts``: where each available vehicle should wait now."""
        return self._json(self._send("GET", f"/v1/fleets/{fleet_id}/posts"))
