"""One target served and the fleet moved, in one compiled call.

:meth:`routing_svc.sa.Fleet.observe` for a target that needs any one vehicle
runs, on a road network, two searches (the fleet's and its back probes',
:meth:`RoadSpace.assign` and :meth:`RoadSpace.arrival_times`), the probe's
back-offs, the mover's step along its route (:meth:`RoadSpace.advance`) and
its new entry (:meth:`RoadSpace.entry`). Each is a small amount of arithmetic,
and the Python glue between them cost several times the searches. Here they
are one numba function, :func:`serve_one`, over columns of the fleet that are
kept between targets (:class:`FleetUpdate`), with one search: the fleet's
search also prices the probes from the labels it computed (a probe matters
only if it arrives before the fleet, and the fleet's search has settled every
class such a probe can be on; see :func:`~routing_svc.network.search.nearest_vehicles`).

The rule is not written twice. The step of eqs. (9)-(10) and the probe's gain
and step are the plain functions of :mod:`routing_svc.sa.step_rule`, compiled
here as they are; the moves (the back probe, the back-off, the walk on one edge,
the entry behind a move) are the kernels of :mod:`routing_svc.network.moves`,
which :class:`RoadSpace` calls too. So a fleet gives bit-identical positions
either way; ``tests/network/test_network_serving.py`` checks that over
thousands of targets. Whatever this call does not cover (a requirement of
several types, annealing noise, a search that reports an error) is left to the
methods.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from routing_svc.network.columns import changed_rows, write_rows
from routing_svc.network.compile import CompiledNetwork
from routing_svc.network.costs import EdgeCosts, check_position
from routing_svc.network.moves import (
    ENTRY_FOUND,
    ENTRY_ON_ROUTE_START,
    back_off_point,
    entry_behind,
    probe_point,
    walk_one_edge,
)
from routing_svc.network.search import (
    STATUS_OK,
    ArcArray,
    SearchBuffers,
    nearest_vehicles,
)
from routing_svc.network.twins import set_twins
from routing_svc.network.walking import walk_spend
from routing_svc.sa.space import Assignment, Served
from routing_svc.sa.step_rule import probe_gains, probe_step, step_amount
from routing_svc.types import FloatArray, Int32Array, IntArray, NetPosition

__all__ = ["FleetUpdate", "refresh_probes", "serve_one"]


_NO_EDGE = -1
"""Edge index of an unknown entry (``None``)."""

Road = tuple[
    Int32Array, ArcArray, Int32Array, Int32Array, FloatArray, FloatArray, FloatArray, IntArray
]
"""The graph and costs the kernels read: ``(arc_indptr, arcs, edge_class, fwd_indptr,
length, cost, rate, rev)`` (:func:`~routing_svc.network.search.nearest_vehicles`'s
class graph and arcs, the forward CSR's index, edge lengths, costs, cost per metre,
reverse edges)."""

Work = tuple[FloatArray, Int32Array, Int32Array, FloatArray, Int32Array, Int32Array, Int32Array]
"""The search's work arrays ``(dist, pred, touched, heap_key, heap_node, head, next)``
(:class:`~routing_svc.network.search.SearchBuffers`)."""


_step_amount = njit(cache=True)(step_amount)
_probe_gains = njit(cache=True)(probe_gains)
_probe_step = njit(cache=True)(probe_step)


@njit(cache=True)
def refresh_probes(
    rate: FloatArray,
    rev: IntArray,
    length: FloatArray,
    window: float,
    veh_edge: IntArray,
    veh_offset: FloatArray,
    entry_edge: IntArray,
    entry_offset: FloatArray,
    probe_edge: IntArray,
    probe_offset: FloatArray,
    either_way: bool,
    rows: IntArray,
) -> None:
    """Rewrite the back probes (and their twins) of the vehicles ``rows``."""
    for i in rows:
        e, s = probe_point(rate, window, veh_edge[i], veh_offset[i], entry_edge[i], entry_offset[i])
        probe_edge[i] = e
        probe_offset[i] = s
    if either_way:
        set_twins(rev, length, probe_edge, probe_offset, rows)


@njit(cache=True)
def _path_cost(
    road: Road,
    work: Work,
    either_way: bool,
    from_edge: int,
    from_offset: float,
    to_edge: int,
    to_offset: float,
) -> float:
    """:meth:`RoadSpace.path_cost` (``inf`` when unreachable): the search with one
    vehicle (and its twin) of speed 1."""
    arc_indptr, arcs, edge_class, _, length, _, rate, rev = road
    dist, pred, touched, heap_key, heap_node, head, nxt = work
    m = 2 if either_way else 1
    edges = np.empty(m, dtype=np.int64)
    offsets = np.empty(m)
    edges[0] = from_edge
    offsets[0] = from_offset
    if either_way:
        set_twins(rev, length, edges, offsets, np.zeros(1, dtype=np.int64))
    found = nearest_vehicles(
        arc_indptr, arcs, edge_class, length, rate, to_edge, to_offset,
        edges, offsets, np.ones(m), np.zeros(m, dtype=np.int64), np.ones(1, dtype=np.int64),
        dist, pred, touched, heap_key, heap_node, head, nxt, 1, np.inf,
    )  # fmt: skip
    if found[0] != STATUS_OK:
        return np.inf
    return float(found[5][found[2]])


@njit(cache=True)
def serve_one(
    road: Road,
    work: Work,
    target_edge: int,
    target_offset: float,
    veh_edge: IntArray,
    veh_offset: FloatArray,
    speed: FloatArray,
    anyone: IntArray,
    one: IntArray,
    probe_edge: IntArray,
    probe_offset: FloatArray,
    entry_edge: IntArray,
    entry_offset: FloatArray,
    gammas: FloatArray,
    power: float,
    window: float,
    either_way: bool,
    backed: IntArray,
) -> tuple[int, int, int, float, float, float, int, bool]:
    """Serve one target that needs any one vehicle; move the fleet's columns in place.

    The vehicle columns (``veh_edge``, ``veh_offset``, with twins when
    ``either_way``, as the search takes them), the probes' columns (likewise)
    and the entries (edge ``-1``: unknown) are updated in place. ``gammas``
    holds each vehicle's step size ``gamma_k`` for its next update, ``power``
    the objective's ``q`` (eqs. (9)-(10)), ``window`` the probe's ``h``
    (``<= 0``: no probe, the paper's rule alone).

    Returns ``(status, detail, mover, completion_time, mover_cost, amount,
    n_backed, reached)``: the fleet search's status (anything but
    ``STATUS_OK`` changes nothing), the mover, its time and path cost, the
    cost it travelled, how many vehicles the probe moved back (their indices,
    in order, are ``backed[:n_backed]``) and whether the mover reached the
    target exactly. The mover's new position and entry are in the columns.
    """
    arc_indptr, arcs, edge_class, _, length, cost, rate, rev = road
    dist, pred, touched, heap_key, heap_node, head, nxt = work
    n = entry_edge.shape[0]
    probing = window > 0.0
    times = np.empty(n)  # the probes' times, priced by the fleet's own search
    if probing:
        found = nearest_vehicles(
            arc_indptr, arcs, edge_class, length, rate, target_edge, target_offset,
            veh_edge, veh_offset, speed, anyone, one,
            dist, pred, touched, heap_key, heap_node, head, nxt, n, np.inf,
            probe_edge, probe_offset, speed, times,
        )  # fmt: skip
    else:
        found = nearest_vehicles(
            arc_indptr, arcs, edge_class, length, rate, target_edge, target_offset,
            veh_edge, veh_offset, speed, anyone, one,
            dist, pred, touched, heap_key, heap_node, head, nxt, n, np.inf,
        )  # fmt: skip
    status, detail, mover_slot, route = found[0], found[1], found[2], found[3]
    if status != STATUS_OK:
        return status, detail, -1, np.nan, np.nan, 0.0, 0, False
    mover = int(found[6][mover_slot])
    completion = found[4][mover_slot]
    mover_cost = found[5][mover_slot]
    amount = _step_amount(gammas[mover], mover_cost, speed[mover], power)
    rows = np.empty(1, dtype=np.int64)

    n_backed = 0
    if probing:  # Fleet._probe; only probes that arrive before the fleet count
        for j in range(n):
            if not _probe_gains(times[j], completion):
                continue
            step = _probe_step(gammas[j], completion - times[j], window)
            e = veh_edge[j]
            moved_e, moved_s = back_off_point(
                rate, e, veh_offset[j], probe_edge[j], probe_offset[j], step
            )
            if moved_e != e:  # RoadSpace.entry without a route: unknown on another edge
                entry_edge[j] = _NO_EDGE
                entry_offset[j] = 0.0
            veh_edge[j] = moved_e
            veh_offset[j] = moved_s
            rows[0] = j
            if either_way:
                set_twins(rev, length, veh_edge, veh_offset, rows)
            refresh_probes(
                rate, rev, length, window, veh_edge, veh_offset, entry_edge, entry_offset,
                probe_edge, probe_offset, either_way, rows,
            )  # fmt: skip
            backed[n_backed] = j
            n_backed += 1
            if j == mover:
                amount = 0.0

    reached = False
    if amount > 0.0:  # RoadSpace.advance
        start_e, start_s = veh_edge[mover], veh_offset[mover]
        e, s = start_e, start_s
        new_e, new_s = target_edge, target_offset
        if either_way and route[0] != e and veh_edge[n + mover] == route[0]:
            e, s = veh_edge[n + mover], veh_offset[n + mover]
        if route.shape[0] == 1:  # walk_route
            reached, new_s = walk_one_edge(rate, target_edge, s, target_offset, amount)
        else:
            k, at = walk_spend(length, cost, rate, route, s, target_offset, amount)
            if k < 0:
                reached = True
            else:
                new_e, new_s = route[k], at
        if reached:
            new_e, new_s = target_edge, target_offset
        if probing:
            _move_entry(
                road, work, either_way, start_e, start_s, new_e, new_s, route,
                entry_edge, entry_offset, mover, window,
            )  # fmt: skip
        veh_edge[mover] = new_e
        veh_offset[mover] = new_s
        rows[0] = mover
        if either_way:
            set_twins(rev, length, veh_edge, veh_offset, rows)
        if probing:
            refresh_probes(
                rate, rev, length, window, veh_edge, veh_offset, entry_edge, entry_offset,
                probe_edge, probe_offset, either_way, rows,
            )  # fmt: skip
    return STATUS_OK, 0, mover, completion, mover_cost, amount, n_backed, reached


@njit(cache=True)
def _move_entry(
    road: Road,
    work: Work,
    either_way: bool,
    old_e: int,
    old_s: float,
    new_e: int,
    new_s: float,
    route: IntArray,
    entry_edge: IntArray,
    entry_offset: FloatArray,
    i: int,
    window: float,
) -> None:
    """Set vehicle ``i``'s entry after a move along ``route`` (:meth:`RoadSpace.entry`)."""
    _, _, _, fwd_indptr, length, cost, rate, rev = road
    if new_e == old_e and new_s >= old_s:
        return
    how, best = entry_behind(
        fwd_indptr, rev, either_way, length, cost, rate, route, new_e, new_s, window
    )
    if how == ENTRY_ON_ROUTE_START:
        if new_e != old_e:
            entry_edge[i] = _NO_EDGE
            entry_offset[i] = 0.0
        return
    if how == ENTRY_FOUND:
        entry_edge[i] = best
        entry_offset[i] = length[best]
        return
    if entry_edge[i] >= 0:
        to_previous = _path_cost(
            road, work, either_way, entry_edge[i], entry_offset[i], new_e, new_s
        )
        if to_previous < np.inf and (to_previous <= window or best < 0):
            return
    entry_edge[i] = best
    entry_offset[i] = length[best] if best >= 0 else 0.0


class FleetUpdate:
    """The columns of one fleet's positions, entries and probes, kept for :func:`serve_one`.

    Parameters
    ----------
    network, costs, buffers, arcs
        The space's graph, edge costs, search buffers and search arcs.
    rev : IntArray
        The network's reverse edges (:func:`~routing_svc.network.twins.reverse_edges`).
    either_way : bool
        Vehicles may leave in either direction (twins).
    speeds : FloatArray
        The vehicles' speeds.
    window : float
        The probe's window, ``<= 0`` for none.

    Notes
    -----
    The work arrays are the space's own, shared with its other searches (each
    leaves them clean, and all of them hold the GIL, so they run one after
    another); the vehicle links are taken once, long enough for this fleet.
    The lists given to :meth:`serve` are the fleet's own: they are updated in
    place, and compared by identity with what the columns were built from, so
    that a change made elsewhere (another kind of update, a restore) is picked
    up before the next search.
    """

    def __init__(
        self,
        network: CompiledNetwork,
        costs: EdgeCosts,
        buffers: SearchBuffers,
        arcs: ArcArray,
        rev: IntArray,
        *,
        either_way: bool,
        speeds: FloatArray,
        window: float,
    ) -> None:
        self.network = network
        self.costs = costs
        self.either_way = either_way
        self.window = window
        n = speeds.shape[0]
        self._n = n
        self._rev = rev
        classes = network.end_classes
        self._road: Road = (
            classes.arc_indptr, arcs, classes.edge_class, network.fwd_indptr,
            network.length, costs.cost, costs.rate, rev,
        )  # fmt: skip
        self._work: Work = (
            buffers.dist, buffers.pred, buffers.touched, buffers.heap_key, buffers.heap_node,
            buffers.head, buffers.vehicle_links(2 * n),
        )  # fmt: skip
        self._speed = np.concatenate((speeds, speeds)) if either_way else speeds.copy()
        self._anyone = np.zeros(self._speed.shape[0], dtype=np.int64)
        self._one = np.ones(1, dtype=np.int64)
        self._backed = np.empty(n, dtype=np.int64)
        width = self._speed.shape[0]
        self._veh_edge = np.zeros(width, dtype=np.int64)
        self._veh_offset = np.zeros(width)
        self._probe_edge = np.zeros(width, dtype=np.int64)
        self._probe_offset = np.zeros(width)
        self._entry_edge = np.full(n, _NO_EDGE, dtype=np.int64)
        self._entry_offset = np.zeros(n)
        self._positions: list[NetPosition] | None = None
        self._entries: list[NetPosition | None] = []
        self._seen: list[NetPosition | None] = []
        self._seen_entries: list[NetPosition | None] = []

    def _sync(self, positions: list[NetPosition], entries: list[NetPosition | None]) -> None:
        """Bring the columns up to date with the lists (rows whose objects changed)."""
        if self._positions is not positions or self._entries is not entries:
            self._positions, self._entries = positions, entries
            self._seen = [None] * self._n
            self._seen_entries = [_UNSEEN] * self._n
        if positions == self._seen and entries == self._seen_entries:
            return  # equal lists (compared by identity first) need no rewrite
        changed = set(changed_rows(positions, self._seen))
        changed.update(changed_rows(entries, self._seen_entries))
        if not changed:
            return
        rows = sorted(changed)
        for i in rows:  # before anything is written
            check_position(self.network, positions[i], what=f"vehicle {i}")
            entry = entries[i]
            if entry is not None:
                check_position(self.network, entry, what=f"entry of vehicle {i}")
        write_rows(self.network, self.either_way, positions, rows, self._veh_edge, self._veh_offset)
        for i in rows:
            entry = entries[i]
            self._entry_edge[i] = _NO_EDGE if entry is None else entry.edge
            self._entry_offset[i] = 0.0 if entry is None else entry.offset
            self._seen[i] = positions[i]
            self._seen_entries[i] = entry
        if self.window > 0.0:
            refresh_probes(
                self.costs.rate, self._rev, self.network.length, self.window,
                self._veh_edge, self._veh_offset, self._entry_edge, self._entry_offset,
                self._probe_edge, self._probe_offset, self.either_way,
                np.array(rows, dtype=np.int64),
            )  # fmt: skip

    def serve(
        self,
        target: NetPosition,
        positions: list[NetPosition],
        entries: list[NetPosition | None],
        gammas: FloatArray,
        power: float,
    ) -> Served[NetPosition] | None:
        """Serve ``target`` (checked to lie on the network) and move the fleet in place.

        ``None``: the search reported an error; nothing changed (the caller's
        own path then raises it).
        """
        self._sync(positions, entries)
        veh_edge, veh_offset = self._veh_edge, self._veh_offset
        entry_edge, entry_offset = self._entry_edge, self._entry_offset
        status, _, mover, completion, mover_cost, amount, n_backed, reached = serve_one(
            self._road, self._work,
            target.edge, target.offset, veh_edge, veh_offset, self._speed, self._anyone,
            self._one, self._probe_edge, self._probe_offset,
            entry_edge, entry_offset, gammas, power, self.window, self.either_way,
            self._backed,
        )  # fmt: skip
        if status != STATUS_OK:
            return None
        seen, seen_entries = self._seen, self._seen_entries
        old = positions[mover]
        backed_off: list[tuple[int, NetPosition]] = []
        for j in self._backed[:n_backed].tolist():
            moved = NetPosition(int(veh_edge[j]), float(veh_offset[j]))
            positions[j] = seen[j] = moved
            entries[j] = seen_entries[j] = self._entry(j)
            backed_off.append((j, moved))
        if amount > 0.0:
            new = target if reached else NetPosition(int(veh_edge[mover]), float(veh_offset[mover]))
            positions[mover] = seen[mover] = new
            entries[mover] = seen_entries[mover] = self._entry(mover)
        return Served(
            mover, completion, mover_cost, amount, old, positions[mover], tuple(backed_off)
        )

    def search(
        self, target: NetPosition, positions: list[NetPosition], entries: list[NetPosition | None]
    ) -> Assignment[NetPosition] | None:
        """The fleet's search for ``target`` alone, with the kept columns:
        :meth:`RoadSpace.assign` for any one vehicle, nothing moved.

        ``None``: the search reported an error (the caller's own path then raises it).

        Raises
        ------
        InvalidInput
            If the target or a position is not on the network.
        """
        check_position(self.network, target, what="target")
        self._sync(positions, entries)
        arc_indptr, arcs, edge_class, _, length, _, rate, _ = self._road
        dist, pred, touched, heap_key, heap_node, head, nxt = self._work
        status, _, slot, route, times, costs, idx = nearest_vehicles(
            arc_indptr, arcs, edge_class, length, rate, target.edge, target.offset,
            self._veh_edge, self._veh_offset, self._speed, self._anyone, self._one,
            dist, pred, touched, heap_key, heap_node, head, nxt, self._n, np.inf,
        )  # fmt: skip
        if status != STATUS_OK:
            return None
        route.flags.writeable = False
        mover = int(idx[slot])
        time = float(times[slot])
        return Assignment((mover,), (time,), mover, time, float(costs[slot]), route)

    def _entry(self, i: int) -> NetPosition | None:
        edge = int(self._entry_edge[i])
        if edge < 0:
            return None
        return NetPosition(edge, float(self._entry_offset[i]))


_UNSEEN = NetPosition(-1, -1.0)
"""Marks an entry the columns hold nothing for (``None`` is a valid entry)."""
