"""Talking to a live service from the dashboard tests: fleets, targets, geometry."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import httpx


@dataclass(frozen=True)
class Edge:
    """A usable edge of the network as ``/geometry`` shows it."""

    id: str
    coords: list[tuple[float, float]]
    length: float

    @property
    def midpoint(self) -> tuple[float, float]:
        """The middle vertex of the edge's shape (a point that lies on the edge)."""
        return self.coords[len(self.coords) // 2]


class ServiceClient:
    """A thin synchronous client of the REST API of one live server."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.http = httpx.Client(base_url=url, timeout=60.0)
        self._geometry: dict[str, Any] | None = None

    def close(self) -> None:
        self.http.close()

    def geometry(self, network: str = "drt") -> dict[str, Any]:
        if self._geometry is None:
            r = self.http.get(f"/v1/networks/{network}/geometry")
            r.raise_for_status()
            self._geometry = r.json()
        return self._geometry

    def edges(self) -> list[Edge]:
        return [
            Edge(
                f["properties"]["id"],
                [(float(x), float(y)) for x, y in f["geometry"]["coordinates"]],
                float(f["properties"]["length"]),
            )
            for f in self.geometry()["features"]
        ]

    def spread_edges(self, count: int) -> list[Edge]:
        """``count`` long-ish edges spread over the network (deterministic)."""
        edges = sorted((e for e in self.edges() if e.length > 30.0), key=lambda e: e.midpoint)
        step = len(edges) / count
        return [edges[int((i + 0.5) * step)] for i in range(count)]

    def create_fleet(self, fleet_id: str, types: list[str], **extra: Any) -> dict[str, Any]:
        """A fleet with one vehicle per entry of ``types`` on edges spread over the network."""
        vehicles = [
            {"id": f"v{i + 1}", "type": t, "position": {"edge": e.id, "offset": 0.0}}
            for i, (t, e) in enumerate(zip(types, self.spread_edges(len(types)), strict=True))
        ]
        r = self.http.post(
            "/v1/fleets", json={"id": fleet_id, "network": "drt", "vehicles": vehicles, **extra}
        )
        assert r.status_code == 201, r.text
        body: dict[str, Any] = r.json()
        return body

    def fleet(self, fleet_id: str) -> dict[str, Any]:
        r = self.http.get(f"/v1/fleets/{fleet_id}")
        r.raise_for_status()
        body: dict[str, Any] = r.json()
        return body

    def post_target(
        self, fleet_id: str, position: dict[str, Any], requires: list[str] | None = None
    ) -> dict[str, Any]:
        body: dict[str, Any] = {"position": position}
        if requires is not None:
            body["requires"] = requires
        r = self.http.post(f"/v1/fleets/{fleet_id}/targets", json=body)
        assert r.status_code == 200, r.text
        result: dict[str, Any] = r.json()
        return result

    def set_state(self, fleet_id: str, vehicle: str, body: dict[str, Any]) -> dict[str, Any]:
        r = self.http.put(f"/v1/fleets/{fleet_id}/vehicles/{vehicle}/state", json=body)
        assert r.status_code == 200, r.text
        result: dict[str, Any] = r.json()
        return result

    def posts(self, fleet_id: str) -> dict[str, Any]:
        r = self.http.get(f"/v1/fleets/{fleet_id}/posts")
        assert r.status_code == 200, r.text
        result: dict[str, Any] = r.json()
        return result

    def post_batch(self, fleet_id: str, targets: list[dict[str, Any]]) -> list[dict[str, Any]]:
        r = self.http.post(f"/v1/fleets/{fleet_id}/targets:batch", json={"targets": targets})
        assert r.status_code == 200, r.text
        results: list[dict[str, Any]] = r.json()["results"]
        return results

    def events(self, fleet_id: str, after: int = 0) -> list[dict[str, Any]]:
        r = self.http.get(f"/v1/fleets/{fleet_id}/events", params={"after": after, "limit": 1000})
        r.raise_for_status()
        items: list[dict[str, Any]] = r.json()["items"]
        return items
