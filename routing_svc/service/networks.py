"""The networks the service knows: compiled graphs, spaces and snappers."""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from routing_svc.errors import InvalidInput, InvalidNetwork, UnknownEdge, UnknownNetwork
from routing_svc.network import CompiledNetwork, RoadSpace, Snapper, load_network
from routing_svc.network.costs import position_arrays
from routing_svc.network.identity import network_sha256
from routing_svc.network.osm_import import looks_like_osm, osm_to_net_bytes
from routing_svc.network.projection import GeoProjection
from routing_svc.network.safe_xml import check_net_xml_file, read_net_bytes
from routing_svc.network.snapping import points_on_edges
from routing_svc.sa.space import Requirement
from routing_svc.service.schemas import EdgePosition, LonLatPosition, Position, XYPosition
from routing_svc.types import NetPosition

SNAP_DISTANCE_M = 500.0
"""Coordinates farther than this from every usable edge are off the network."""


DESCRIBED_PLACES = 65_536
"""Descriptions a network keeps (:meth:`NetworkEntry.describe`)."""


@dataclass
class NetworkEntry:
    """One loaded network with its spaces (one per cost kind) and snapper."""

    id: str
    name: str
    path: Path
    network: CompiledNetwork
    snapper: Snapper
    _spaces: dict[str, RoadSpace] = field(default_factory=dict)
    _geometry: dict[str, Any] | None = None
    _described: dict[NetPosition, dict[str, Any]] = field(default_factory=dict)

    def space(self, cost: str) -> RoadSpace:
        """The free-flow space for ``cost`` (``length`` or ``time``), built once."""
        if cost not in ("length", "time"):
            raise InvalidInput(f"cost must be 'length' or 'time', got {cost!r}")
        if cost not in self._spaces:
            self._spaces[cost] = RoadSpace(self.network, cost=cost)  # type: ignore[arg-type]
        return self._spaces[cost]

    def warm_up(self) -> None:
        """Run each compiled kernel once (a search, a move, a description), so that
        the first request does not pay for loading or compiling them."""
        here = NetPosition(0, 0.0)
        space = self.space("length")
        one = Requirement(np.zeros(1, dtype=np.int64), np.ones(1, dtype=np.int64))
        found = space.assign(here, [here], np.ones(1), one)
        space.advance(here, here, found.route, 0.0)
        space.serving(np.ones(1), 1.0).serve(here, [here], [None], np.ones(1), 1.0)
        self.describe(here)

    def resolve(self, position: Position) -> NetPosition:
        """A position from the API (edge/offset, x/y or lon/lat) on this network."""
        if isinstance(position, EdgePosition):
            return self.resolve_edge(position.edge, position.offset)
        if isinstance(position, XYPosition):
            return self.snapper.snap_xy([position.x], [position.y], max_distance=SNAP_DISTANCE_M)[0]
        if isinstance(position, LonLatPosition):
            return self.snapper.snap_lonlat(
                [position.lon], [position.lat], max_distance=SNAP_DISTANCE_M
            )[0]
        raise InvalidInput("unknown position form")

    def resolve_edge(self, edge: str, offset: float) -> NetPosition:
        """The place ``offset`` metres along the edge with SUMO id ``edge``.

        Raises
        ------
        UnknownEdge
            If the edge is not a usable edge of this network.
        InvalidInput
            If the offset is not a number from 0 to the edge's length.
        """
        index = self.network.edge_index.get(edge)
        if index is None:
            raise UnknownEdge(f"edge {edge!r} is not a usable edge of network {self.id!r}")
        length = float(self.network.length[index])
        if offset > length:
            raise InvalidInput(
                f"offset {offset} is beyond the end of edge {edge!r} (length {length})"
            )
        if not offset >= 0.0:  # also NaN
            raise InvalidInput(f"offset {offset} on edge {edge!r} is not a number from 0 up")
        # + 0.0: an offset of -0.0 is the edge's start, 0.0 (positions that compare equal
        # are then also written the same)
        return NetPosition(index, float(offset) + 0.0)

    def describe(self, position: NetPosition) -> dict[str, Any]:
        """``edge, offset, x, y`` (and ``lon, lat`` where the network has a projection).

        A fleet's answers describe the same few places again and again (its
        references, the places its calls come from), so the last
        :data:`DESCRIBED_PLACES` descriptions are kept; each answer gets its own copy.
        """
        kept = self._described.get(position)
        if kept is None:
            if len(self._described) >= DESCRIBED_PLACES:
                self._described.clear()
            kept = self._described[position] = self._description(position)
        return dict(kept)

    def describe_many(self, positions: Sequence[NetPosition]) -> list[dict[str, Any]]:
        """:meth:`describe` of each position, computed together (the same arithmetic,
        :func:`~routing_svc.network.snapping.points_on_edges`); nothing is kept.

        Raises
        ------
        InvalidInput
            If a position is not on the network.
        """
        network = self.network
        edges, offsets = position_arrays(network, positions, what="position")
        xs, ys = points_on_edges(network, edges, offsets)
        projection = self._projection()
        if projection is None:
            return [
                self._place(p, x, y, None)
                for p, x, y in zip(positions, xs.tolist(), ys.tolist(), strict=True)
            ]
        lons, lats = projection.to_lonlat(xs, ys)
        return [
            self._place(p, x, y, (lon, lat))
            for p, x, y, lon, lat in zip(
                positions, xs.tolist(), ys.tolist(), lons.tolist(), lats.tolist(), strict=True
            )
        ]

    def _description(self, position: NetPosition) -> dict[str, Any]:
        x, y = self.space("length").xy(position)
        projection = self._projection()
        lonlat = None if projection is None else projection.point_to_lonlat(x, y)
        return self._place(position, x, y, lonlat)

    def _projection(self) -> GeoProjection | None:
        """The network's geographic projection where it is supported."""
        projection = self.network.projection
        return projection if projection is not None and projection.supported else None

    def _place(
        self, position: NetPosition, x: float, y: float, lonlat: tuple[float, float] | None
    ) -> dict[str, Any]:
        """A description (:meth:`describe`) from its coordinates."""
        out: dict[str, Any] = {
            "edge": self.network.edge_ids[position.edge],
            "offset": position.offset,
            "x": x,
            "y": y,
        }
        if lonlat is not None:
            out["lon"], out["lat"] = lonlat
        return out

    def summary(self) -> dict[str, Any]:
        """The network as ``GET /v1/networks/{id}`` shows it."""
        net = self.network
        red = net.reduction
        return {
            "id": self.id,
            "name": self.name,
            "junctions": net.n_junctions,
            "edges": net.n_edges,
            "usable_edges": red.usable_edges,
            "dropped_edges": red.dropped_edges,
            "bounds": list(net.bounds),
            "has_projection": net.projection is not None,
            "sha256": net.source_sha256,
            "vclass": net.vclass,
        }

    def geometry(self) -> dict[str, Any]:
        """GeoJSON FeatureCollection of the usable edges in network coordinates."""
        if self._geometry is None:
            net = self.network
            features = []
            for i, edge_id in enumerate(net.edge_ids):
                pts = net.shape_xy[net.shape_offsets[i] : net.shape_offsets[i + 1]]
                features.append(
                    {
                        "type": "Feature",
                        "geometry": {
                            "type": "LineString",
                            "coordinates": [
                                [round(float(x), 2), round(float(y), 2)] for x, y in pts
                            ],
                        },
                        "properties": {
                            "id": edge_id,
                            "length": float(net.length[i]),
                            "speed": float(net.speed[i]),
                        },
                    }
                )
            self._geometry = {
                "type": "FeatureCollection",
                "bbox": list(net.bounds),
                "features": features,
            }
        return self._geometry


class NetworkRegistry:
    """Networks by id: named at start-up or uploaded (kept under ``data_dir``)."""

    def __init__(self, *, data_dir: Path, max_bytes: int) -> None:
        self.data_dir = data_dir
        self.max_bytes = max_bytes
        self._entries: dict[str, NetworkEntry] = {}
        self._lock = threading.Lock()

    def __contains__(self, network_id: str) -> bool:
        return network_id in self._entries

    def get(self, network_id: str) -> NetworkEntry:
        try:
            return self._entries[network_id]
        except KeyError:
            raise UnknownNetwork(f"no network {network_id!r}") from None

    def all(self) -> list[NetworkEntry]:
        return [self._entries[k] for k in sorted(self._entries)]

    def load(self, network_id: str, path: Path, *, name: str | None = None) -> NetworkEntry:
        """Load (or return the already loaded) network from a file."""
        with self._lock:
            if network_id in self._entries:
                return self._entries[network_id]
            if not path.is_file():
                raise UnknownNetwork(f"network file {str(path)!r} does not exist")
            check_net_xml_file(path)
            network = load_network(path)
            entry = NetworkEntry(network_id, name or network_id, path, network, Snapper(network))
            self._entries[network_id] = entry
            return entry

    def store_upload(self, data: bytes | bytearray) -> tuple[str, Path, bool]:
        """Check an uploaded network and write it under ``data_dir``; return its identity
        (:func:`~routing_svc.network.identity.network_sha256`, the same for the ``.gz``
        and the plain file), its path and whether this call wrote the file (so that a
        caller that then refuses the network can take it back, :meth:`discard_upload`).

        An upload whose root element is ``<osm>`` is an OpenStreetMap extract: it is
        screened with the same limits and converted by netconvert
        (:func:`~routing_svc.network.osm_import.osm_to_net_bytes`) first; the same
        extract always gives the same network.
        """
        if not data:
            raise InvalidNetwork(
                "empty upload: send the bytes of a .net.xml or .net.xml.gz, "
                "or of an OpenStreetMap .osm[.xml][.gz]"
            )
        if looks_like_osm(data):
            data = osm_to_net_bytes(data, max_bytes=self.max_bytes)
        xml = read_net_bytes(data, max_bytes=self.max_bytes)
        digest = network_sha256(xml)
        self.data_dir.mkdir(parents=True, exist_ok=True)
        path = self.data_dir / f"{digest}.net.xml"
        if path.exists():
            return digest, path, False
        tmp = path.with_suffix(".tmp")
        tmp.write_bytes(xml)
        tmp.replace(path)
        return digest, path, True

    def discard_upload(self, path: Path) -> None:
        """Remove an uploaded file that no registered network uses (a refused upload)."""
        with self._lock:
            if all(entry.path != path for entry in self._entries.values()):
                path.unlink(missing_ok=True)
