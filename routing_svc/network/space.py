"""The road-network space: the ``Space[NetPosition]`` that the SA core runs on.

Positions are ``(edge, offset)`` pairs on a :class:`CompiledNetwork`. The cost
from a vehicle at ``(e, s)`` to a target at ``(t, s_t)`` is the forward
distance ``s_t - s`` when ``e == t`` and ``s <= s_t``, else the rest of ``e``,
the edges of the cheapest connection path, and ``s_t`` of ``t``; every part
of an edge costs in proportion to its length (metres, or seconds at the
edge's travel time). The lengths of internal junction lanes are ignored:
a connection costs nothing. See :mod:`routing_svc.network.search`.
"""

from __future__ import annotations

import functools
import threading
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from routing_svc.errors import InvalidInput, UnknownEdge, UnmetRequirement, Unreachable
from routing_svc.network.columns import SearchColumns
from routing_svc.network.compile import CompiledNetwork
from routing_svc.network.costs import (
    CostKind,
    DistanceRows,
    EdgeCosts,
    check_position,
    cost_matrix,
    position_arrays,
)
from routing_svc.network.moves import (
    ENTRY_FOUND,
    ENTRY_ON_ROUTE_START,
    NO_ROUTE,
    back_off_point,
    entry_behind,
    probe_point,
)
from routing_svc.network.search import (
    STATUS_BAD_COUNTS,
    STATUS_BAD_GROUP,
    STATUS_BAD_POSITION,
    STATUS_BAD_SPEED,
    STATUS_UNMET,
    STATUS_UNREACHABLE,
    SearchBuffers,
    arrivals_before,
    nearest_vehicles,
    search_arcs,
)
from routing_svc.network.serving import FleetUpdate
from routing_svc.network.snapping import point_on_edge
from routing_svc.network.stops import candidate_references, junction_ahead
from routing_svc.network.twins import reverse_edges, twin, twin_columns
from routing_svc.network.walking import check_route, random_walk, walk_route
from routing_svc.sa.space import Assignment, Requirement
from routing_svc.types import FloatArray, Int32Array, IntArray, NetPosition

__all__ = ["RoadSpace"]

_TWIN_BLOCK_CELLS = 2**24
"""Cells of the twin sources' costs :meth:`RoadSpace.cost_matrix` holds at a time: the
either-way minimum takes no second matrix of the whole size."""


_TYPICAL_SEED = 0
_TYPICAL_SOURCES = 32
_TYPICAL_TARGETS = 256
_ONE_VEHICLE = Requirement(
    vehicle_groups=np.zeros(1, dtype=np.int64), counts=np.ones(1, dtype=np.int64)
)
_UNIT_SPEED = np.ones(1)


class _SharedBuffers:
    """Search buffers allocated on first use, shared by a space and the spaces derived from it."""

    def __init__(self, network: CompiledNetwork) -> None:
        self._network = network
        self._buffers: SearchBuffers | None = None

    def get(self) -> SearchBuffers:
        if self._buffers is None:
            classes = self._network.end_classes
            self._buffers = SearchBuffers(classes.n_classes, classes.arc_edge.shape[0])
        return self._buffers


class RoadSpace:
    """A SUMO road network as a space of ``NetPosition``.

    Parameters
    ----------
    network : CompiledNetwork
        The compiled network (shared, never modified).
    cost : {"length", "time"}
        Edge cost: length in metres, or free-flow travel time
        ``length / speed`` in seconds.
    either_way : bool
        A vehicle waiting at its position on a two-way street may leave in
        either direction (it turns around at the curb; see
        :mod:`routing_svc.network.twins`). ``False`` gives the strictly
        directed model: a vehicle leaves only forward along its edge.

    Notes
    -----
    The search's work arrays are allocated on first use and shared by this
    space and the spaces derived from it with :meth:`with_travel_times`; the
    compiled search holds the GIL and leaves them clean, so calls from several
    threads are safe and run one after another.
    """

    def __init__(
        self, network: CompiledNetwork, *, cost: CostKind = "length", either_way: bool = True
    ) -> None:
        self.network = network
        self._costs = EdgeCosts.free_flow(network, cost)
        self._rows = DistanceRows(network, self._costs)
        self._buffers = _SharedBuffers(network)
        self._columns = SearchColumns(network, either_way=either_way)
        self._typical: float | None = None
        self.either_way = either_way

    @classmethod
    def _derived(cls, parent: RoadSpace, costs: EdgeCosts) -> RoadSpace:
        space = cls.__new__(cls)
        space.network = parent.network
        space._costs = costs
        space._rows = DistanceRows(parent.network, costs)
        space._buffers = parent._buffers
        space._columns = parent._columns
        space._typical = None
        space.either_way = parent.either_way
        return space

    def __reduce__(self) -> tuple[Callable[..., RoadSpace], tuple[object, ...]]:
        """Pickled as its network, edge costs and turning rule (another process
        allocates its own search buffers)."""
        return (_rebuilt, (self.network, self._costs, self.either_way))

    @property
    def cost_kind(self) -> CostKind:
        """``"length"`` (metres) or ``"time"`` (seconds)."""
        return self._costs.kind

    @property
    def edge_costs(self) -> EdgeCosts:
        """Cost and cost per metre of every edge (read-only arrays)."""
        return self._costs

    def with_travel_times(self, times: Mapping[str, float]) -> RoadSpace:
        """A space on the same graph with the travel times (s) of some edges replaced.

        Parameters
        ----------
        times : Mapping[str, float]
            New travel time of each listed SUMO edge id; other edges keep theirs.

        Raises
        ------
        InvalidInput
            If this space's cost is not ``"time"``, or a time is not finite and > 0.
        UnknownEdge
            If an edge id is not in the network.
        """
        return RoadSpace._derived(self, self._costs.with_travel_times(self.network, times))

    def search_buffer_bytes(self) -> int:
        """Bytes of the search's work arrays (allocated on first use)."""
        return self._buffers.get().nbytes()

    def assign(
        self,
        target: NetPosition,
        positions: list[NetPosition],
        speeds: FloatArray,
        requirement: Requirement,
    ) -> Assignment[NetPosition]:
        """Find the fastest vehicles of every requirement group with one search.

        Runs one early-exit Dijkstra from ``target`` on the reverse graph of
        end-state classes, the edges grouped by successor set
        (:func:`routing_svc.network.search.nearest_vehicles`). Vehicle ``i``
        arrives after ``cost_i / speeds[i]``; ties break by the lower index.
        The route of the result is the mover's edge path (an array of edge
        indices from its edge to the target's edge).

        Raises
        ------
        InvalidInput
            If the target, a position, a speed or the requirement is invalid.
        UnmetRequirement
            If a group has fewer vehicles than it needs.
        Unreachable
            If a group has too few vehicles that can reach the target.
        """
        _, _, mover_slot, route, best_time, best_cost, best_idx = self._search(
            target, positions, speeds, requirement, np.inf
        )
        route.flags.writeable = False
        if mover_slot < 0:  # ``requirement.mover_groups == 0``: nobody moves
            return Assignment(
                tuple(best_idx.tolist()), tuple(best_time.tolist()), -1, 0.0, 0.0, route
            )
        return Assignment(
            served_by=tuple(best_idx.tolist()),
            times=tuple(best_time.tolist()),
            mover=int(best_idx[mover_slot]),
            completion_time=float(best_time[mover_slot]),
            mover_cost=float(best_cost[mover_slot]),
            route=route,
        )

    def _search(
        self,
        target: NetPosition,
        positions: list[NetPosition],
        speeds: FloatArray,
        requirement: Requirement,
        cutoff: float,
    ) -> tuple[int, int, int, IntArray, FloatArray, FloatArray, Int32Array]:
        """Run :func:`~routing_svc.network.search.nearest_vehicles`; raise its errors."""
        net = self.network
        check_position(net, target, what="target")
        edges, offsets = self._columns.of(positions)
        speed = np.ascontiguousarray(speeds, dtype=np.float64)
        groups, counts = _requirement_arrays(requirement, len(positions))
        if speed.shape != (len(positions),):
            raise InvalidInput("speeds must hold one value per vehicle")
        n = len(positions)
        if self.either_way and n:  # a twin has its vehicle's speed and group
            speed = np.concatenate((speed, speed))
            groups = np.concatenate((groups, groups))
        buffers = self._buffers.get()
        classes = net.end_classes
        found = nearest_vehicles(
            classes.arc_indptr, search_arcs(classes, self._costs), classes.edge_class,
            net.length, self._costs.rate,
            target.edge, float(target.offset), edges, offsets, speed, groups, counts,
            buffers.dist, buffers.pred, buffers.touched, buffers.heap_key, buffers.heap_node,
            buffers.head, buffers.vehicle_links(edges.shape[0]), max(n, 1), cutoff,
            None, None, None, None,
            -1 if requirement.mover_groups is None else requirement.mover_groups,
        )  # fmt: skip
        status, detail = found[0], found[1]
        if status == STATUS_BAD_POSITION:
            check_position(net, positions[detail], what=f"vehicle {detail}")
        if status == STATUS_BAD_GROUP:
            raise InvalidInput(f"group of vehicle {detail} is outside the requirement's groups")
        if status == STATUS_BAD_COUNTS:
            raise InvalidInput("requirement counts must be >= 0 and need at least one vehicle")
        if status == STATUS_BAD_SPEED:
            raise InvalidInput(f"speed of vehicle {detail} must be finite and > 0")
        if status == STATUS_UNMET:
            raise UnmetRequirement(
                f"group {detail} needs {counts[detail]} vehicle(s), the fleet has "
                f"{int((groups == detail).sum())}"
            )
        if status == STATUS_UNREACHABLE:
            raise Unreachable(
                f"fewer than {counts[detail]} vehicle(s) of group {detail} can reach the target"
            )
        return found

    def arrival_times(
        self, target: NetPosition, positions: list[NetPosition], speeds: FloatArray, cutoff: float
    ) -> FloatArray:
        """Each vehicle's travel time to ``target`` if it is below ``cutoff``, else ``inf``.

        One search (each vehicle its own group) that stops once no unseen
        vehicle can arrive before ``cutoff``, so its work grows with the cutoff,
        not with the fleet: what :meth:`Fleet._probe` needs.
        """
        n = len(positions)
        found = self._search(target, positions, speeds, _each_its_own(n), cutoff)
        return arrivals_before(n, found[4], found[6], cutoff)

    def serving(self, speeds: FloatArray, window: float) -> FleetUpdate:
        """The compiled single-target update of a fleet with these speeds
        (:class:`~routing_svc.sa.space.SingleTargetServing`); ``window <= 0``: no probe."""
        net = self.network
        return FleetUpdate(
            net,
            self._costs,
            self._buffers.get(),
            search_arcs(net.end_classes, self._costs),
            reverse_edges(net),
            either_way=self.either_way,
            speeds=np.ascontiguousarray(speeds, dtype=np.float64),
            window=float(window),
        )

    def path_cost(self, a: NetPosition, b: NetPosition) -> float:
        """Directed cost from position ``a`` to position ``b``.

        Raises
        ------
        InvalidInput
            If a position is not on the network.
        Unreachable
            If ``b`` cannot be reached from ``a``.
        """
        check_position(self.network, a, what="source")
        return self.assign(b, [a], _UNIT_SPEED, _ONE_VEHICLE).mover_cost

    def cost_matrix(
        self, sources: Sequence[NetPosition], targets: Sequence[NetPosition]
    ) -> FloatArray:
        """Directed costs from every source to every target, shape ``(len(sources), len(targets))``.

        One compiled Dijkstra per distinct source edge not among the space's
        recently used ones (see :func:`routing_svc.network.costs.cost_matrix`).
        """
        edges, offsets = position_arrays(self.network, sources, what="source")
        columns = position_arrays(self.network, targets, what="target")
        costs = cost_matrix(self._rows, (edges, offsets), columns)
        if self.either_way and edges.size:
            twin_edges, twin_offsets = twin_columns(self.network, edges, offsets)
            rows = np.flatnonzero(twin_edges >= 0)
            block = max(1, _TWIN_BLOCK_CELLS // max(costs.shape[1], 1))
            for lo in range(0, rows.size, block):
                part = rows[lo : lo + block]
                alt = cost_matrix(self._rows, (twin_edges[part], twin_offsets[part]), columns)
                np.minimum(costs[part], alt, out=alt)
                costs[part] = alt
        return costs

    def advance(
        self, position: NetPosition, target: NetPosition, route: object, amount: float
    ) -> NetPosition:
        """Move ``position`` a cost ``amount`` along ``route`` toward ``target``.

        ``route`` is the one :meth:`assign` returned for this position and target.

        An ``amount`` at least the route's cost gives exactly ``target``.

        Raises
        ------
        InvalidInput
            If a position, the route or the amount is invalid.
        """
        check_position(self.network, position, what="position")
        check_position(self.network, target, what="target")
        if (
            self.either_way
            and isinstance(route, np.ndarray)
            and route.shape[0] > 0
            and int(route[0]) != position.edge
        ):
            other = twin(self.network, position)
            if other is not None and other.edge == int(route[0]):
                position = other
        edges = check_route(self.network, position, target, route)
        return walk_route(self.network, self._costs, position, target, edges, amount)

    def junction_ahead(
        self, position: NetPosition, route: object
    ) -> tuple[NetPosition, float] | None:
        """The first junction ahead of ``position`` along ``route`` (from :meth:`assign`)
        and the cost to it; ``None`` if the route ends before one
        (:func:`routing_svc.network.stops.junction_ahead`)."""
        if not isinstance(route, np.ndarray) or route.ndim != 1 or route.shape[0] == 0:
            raise InvalidInput("route must be a non-empty 1-d array of edge indices")
        return junction_ahead(self.network, self._costs, position, route.tolist())

    def candidate_references(
        self, sample: Sequence[NetPosition], fixed: Sequence[NetPosition]
    ) -> list[NetPosition]:
        """``fixed``, then the sample's targets and the ends of their edges, without repeats
        (:func:`routing_svc.network.stops.candidate_references`)."""
        return candidate_references(self.network, sample, fixed)

    def back_probes(
        self,
        positions: list[NetPosition],
        window: float,
        entries: list[NetPosition | None],
    ) -> list[NetPosition]:
        """Per reference, the point a cost ``window`` behind it, or where it entered its edge.

        On its own edge when the offset allows; else its entry, the end of the
        edge the reference came from (that junction, with that edge's turns);
        else (entry unknown) the start of its edge.
        """
        network = self.network
        rate = self._costs.rate
        length = network.length_values
        n_edges = len(length)
        probes: list[NetPosition] = []
        for position, entry in zip(positions, entries, strict=True):
            edge, offset = position
            if not (
                type(edge) is int
                and type(offset) is float
                and 0 <= edge < n_edges
                and 0.0 <= offset <= length[edge]
            ):
                check_position(network, position, what="position")
            at, behind = probe_point(
                rate,
                window,
                edge,
                offset,
                -1 if entry is None else entry.edge,
                0.0 if entry is None else entry.offset,
            )
            probes.append(NetPosition(int(at), float(behind)))
        return probes

    def back_off(self, position: NetPosition, probe: NetPosition, amount: float) -> NetPosition:
        """Move ``position`` a cost ``amount`` back toward its probe, not past it."""
        edge, offset = back_off_point(
            self._costs.rate, position.edge, position.offset, probe.edge, probe.offset, amount
        )
        return NetPosition(int(edge), float(offset))

    def entry(
        self,
        old: NetPosition,
        new: NetPosition,
        route: object,
        previous: NetPosition | None,
        window: float,
    ) -> NetPosition | None:
        """The junction behind ``new`` whose other turns the reference gave up.

        For a reference moved from ``old`` to ``new`` along ``route`` (``None``
        for a move without one), with ``previous`` the entry of ``old``. An
        entry is the end of an edge where the reference had a choice
        (:func:`~routing_svc.network.moves.branches`; ends of edges with a single
        turn reach exactly what the start of the next edge reaches, so they are
        skipped): the farthest
        such junction within a cost ``window`` behind ``new`` along the route,
        or ``previous`` when still within it, else the nearest one behind.

        ``previous`` is kept when the reference stayed on its edge (moved forward
        on it, or back without a route). ``None`` means unknown: it left from
        the twin of ``old`` and stayed on that edge, or it moved to another edge
        without a route (backed off onto its entry, or perturbed by annealing).
        """
        if new.edge == old.edge and new.offset >= old.offset:
            return previous
        net, costs = self.network, self._costs
        how, edge = entry_behind(
            net.fwd_indptr,
            reverse_edges(net),
            self.either_way,
            net.length,
            costs.cost,
            costs.rate,
            route if isinstance(route, np.ndarray) else NO_ROUTE,
            new.edge,
            new.offset,
            window,
        )
        if how == ENTRY_ON_ROUTE_START:
            return previous if new.edge == old.edge else None
        best = None if edge < 0 else NetPosition(int(edge), float(net.length[edge]))
        if how == ENTRY_FOUND:
            return best
        if previous is not None:
            try:
                if self.path_cost(previous, new) <= window or best is None:
                    return previous
            except Unreachable:
                pass
        return best

    def perturb(
        self, position: NetPosition, amount: float, rng: np.random.Generator
    ) -> NetPosition:
        """Drive a cost ``amount`` forward from ``position``, choosing successors at random."""
        check_position(self.network, position, what="position")
        return random_walk(self.network, self._costs, position, amount, rng)

    def typical_cost(self) -> float:
        """The median cost between edge midpoints of a fixed random sample.

        Draws (with a fixed seed, so the value is deterministic) up to 32
        source and 256 target edges, and returns the median of the costs from
        the middle of each source edge to the middle of each target edge.
        Computed once per space.
        """
        if self._typical is None:
            rng = np.random.default_rng(_TYPICAL_SEED)
            n = self.network.n_edges
            half = self.network.length / 2.0
            picks = [
                rng.choice(n, size=min(n, size), replace=False)
                for size in (_TYPICAL_SOURCES, _TYPICAL_TARGETS)
            ]
            sources, targets = ([NetPosition(int(e), float(half[e])) for e in p] for p in picks)
            self._typical = float(np.median(self.cost_matrix(sources, targets)))
        return self._typical

    def encode(self, position: NetPosition) -> dict[str, object]:
        """``{"edge": <SUMO edge id>, "offset": <metres>}``; floats round-trip exactly."""
        check_position(self.network, position, what="position")
        return {"edge": self.network.edge_ids[position.edge], "offset": float(position.offset)}

    def encode_many(self, positions: Sequence[NetPosition]) -> list[dict[str, object]]:
        """:meth:`encode` of each position, checked together."""
        position_arrays(self.network, positions, what="position")
        ids = self.network.edge_ids
        return [{"edge": ids[p.edge], "offset": float(p.offset)} for p in positions]

    def decode(self, data: dict[str, object]) -> NetPosition:
        """Inverse of :meth:`encode`.

        Raises
        ------
        InvalidInput
            If a key is missing or the offset is not a finite number on the edge.
        UnknownEdge
            If the edge id is not in the network.
        """
        if not isinstance(data, dict) or "edge" not in data or "offset" not in data:
            raise InvalidInput("a position needs the keys 'edge' and 'offset'")
        edge_id, offset = data["edge"], data["offset"]
        if not isinstance(edge_id, str):
            raise InvalidInput("a position's 'edge' must be a SUMO edge id (string)")
        edge = self.network.edge_index.get(edge_id)
        if edge is None:
            raise UnknownEdge(f"unknown edge {edge_id!r}")
        if isinstance(offset, bool) or not isinstance(offset, int | float):
            raise InvalidInput("a position's 'offset' must be a number")
        position = NetPosition(edge, float(offset))
        check_position(self.network, position, what="position")
        return position

    def xy(self, position: NetPosition) -> tuple[float, float]:
        """Network coordinates of ``position`` on its edge's shape."""
        check_position(self.network, position, what="position")
        return point_on_edge(self.network, position.edge, position.offset)

    def lonlat(self, position: NetPosition) -> tuple[float, float]:
        """``(lon, lat)`` in WGS84 degrees of ``position``.

        Raises
        ------
        InvalidInput
            If the network has no (supported) geographic projection.
        """
        projection = self.network.projection
        if projection is None:
            raise InvalidInput("the network has no geographic projection")
        x, y = self.xy(position)
        lon, lat = projection.to_lonlat(x, y)
        return float(lon), float(lat)


@functools.lru_cache(maxsize=64)
def _each_its_own(n: int) -> Requirement:
    """The requirement of ``n`` vehicles each in a group of its own, one needed per group."""
    groups = np.arange(n, dtype=np.int64)
    counts = np.ones(n, dtype=np.int64)
    return Requirement(groups, counts)


def _requirement_arrays(requirement: Requirement, n_vehicles: int) -> tuple[IntArray, IntArray]:
    """Contiguous int64 views of the requirement's groups and counts, shape-checked.

    Their values are checked by the search itself.
    """
    try:
        groups = np.ascontiguousarray(requirement.vehicle_groups, dtype=np.int64)
        counts = np.ascontiguousarray(requirement.counts, dtype=np.int64)
    except (TypeError, ValueError, AttributeError):
        raise InvalidInput("a requirement needs integer vehicle groups and counts") from None
    if groups.shape != (n_vehicles,):
        raise InvalidInput("the requirement must give one group per vehicle")
    if counts.ndim != 1:
        raise InvalidInput("requirement counts must be a 1-d array")
    movers = requirement.mover_groups
    if movers is not None and not 0 <= movers <= counts.shape[0]:
        raise InvalidInput("mover_groups must name a prefix of the requirement's groups")
    return groups, counts


_REBUILT_KEPT = 4
"""Spaces a process keeps of those it unpickled (:func:`_rebuilt`)."""

_rebuilt_spaces: OrderedDict[tuple[str, str, str, bool, bytes], RoadSpace] = OrderedDict()
_rebuilt_lock = threading.Lock()


def _rebuilt(network: CompiledNetwork, costs: EdgeCosts, either_way: bool) -> RoadSpace:
    """A pickled :class:`RoadSpace` (:meth:`RoadSpace.__reduce__`).

    A process that unpickles the same network, costs and turning rule again (a
    consolidation worker, job after job) gets the space it built the first time, with
    the rows it has memoised.
    """
    key = (network.source_sha256, network.vclass, costs.kind, either_way, costs.cost.tobytes())
    with _rebuilt_lock:
        kept = _rebuilt_spaces.get(key)
        if kept is not None:
            _rebuilt_spaces.move_to_end(key)
            return kept
    space = RoadSpace._derived(RoadSpace(network, cost=costs.kind, either_way=either_way), costs)
    with _rebuilt_lock:
        _rebuilt_spaces[key] = space
        while len(_rebuilt_spaces) > _REBUILT_KEPT:
            _rebuilt_spaces.popitem(last=False)
    return space
