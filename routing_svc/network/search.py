"""Nearest-vehicle search: one early-exit Dijkstra from the target, numba-compiled.

Costs on the edge graph
-----------------------
Edge ``e`` has a length ``L[e]`` (m) and a cost ``c[e]`` (m or s); a part of
length ``d`` of the edge costs ``d * rate[e]`` with ``rate = c / L``. The cost
from a vehicle at ``(e, s)`` to a target at ``(t, s_t)`` is

- ``(s_t - s) * rate[t]`` if ``e == t`` and ``s <= s_t``;
- else ``(L[e] - s) * rate[e] + h[e]``, where ``h[e]`` is the cost from the
  end of ``e`` to the target: ``h[e] = min`` over successors ``y`` of ``e`` of
  ``s_t * rate[t]`` if ``y == t`` and ``c[y] + h[y]`` otherwise.

The search over end-state classes
---------------------------------
``h[e]`` depends only on the successor set of ``e``, so edges with the same
successor set (an *end-state class*, see
:class:`routing_svc.network.layout.EndStateClasses`) share one value ``H``.
The search computes ``H`` by Dijkstra on the reverse class graph: settling
class ``x`` (key ``H[x]``) relaxes, for every edge ``y`` of class ``x``
(cost ``c[y]``), every class whose edges have ``y`` as a successor. It is
seeded with ``s_t * rate[t]`` at the classes that have ``t`` as a successor.
This is exactly Dijkstra on the edge graph with the equal labels merged (the
same sums, in the same order), so answers, costs and ties are unchanged;
on a grid from ``netgenerate`` it settles a quarter of the nodes. Turn
restrictions and one-way streets only make the classes smaller.

Early exit
----------
Settling class ``x`` prices the vehicles on its edges (except those ahead of
the target on the target edge, priced up front); no vehicle on an unsettled
class can cost less than the smallest key on the heap, so for a group whose
fastest vehicle has speed ``v_max`` no unseen vehicle can arrive before
``key / v_max``. The search stops as soon as every group has its ``count``
best vehicles and the last of them arrives strictly before that bound, so
ties break by the lower vehicle index exactly as a full search would.

Once every group has its vehicles, a class whose key would exceed that bound
for every group can no longer matter; such classes are not even put on the
heap.

Memory
------
The search is bound by memory latency (a query touches a few hundred
classes scattered over megabytes of arrays), not by arithmetic. So every
arc is one 16-byte record of its edge's cost, the class it leads to and the
edge (:func:`search_arcs`: the arcs of a class share a cache line), the heap
is 4-ary (:mod:`routing_svc.network.heap`), and when a class goes on the
heap the cache lines that settling it will read are prefetched.

The mover's path
----------------
``pred[x]`` is the edge that a vehicle at the end of an edge of class ``x``
takes next on a shortest path, so the mover's edge path is its own edge
``e``, then ``pred[class(e)]``, ``pred[class(pred[class(e)])]``, ... up to
the target edge.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from llvmlite import binding as llvm_binding
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from routing_svc.network.costs import EdgeCosts, position_columns
from routing_svc.network.heap import heap_pop, heap_push
from routing_svc.network.layout import EndStateClasses
from routing_svc.types import FloatArray, Int32Array, IntArray, NetPosition

__all__ = [
    "ARC_DTYPE",
    "STATUS_BAD_COUNTS",
    "STATUS_BAD_GROUP",
    "STATUS_BAD_POSITION",
    "STATUS_BAD_SPEED",
    "STATUS_OK",
    "STATUS_UNMET",
    "STATUS_UNREACHABLE",
    "SearchBuffers",
    "arrivals_before",
    "fleet_columns",
    "nearest_vehicles",
    "search_arcs",
]

STATUS_OK = 0
STATUS_UNMET = 1
STATUS_UNREACHABLE = 2
STATUS_BAD_POSITION = 3
STATUS_BAD_SPEED = 4
STATUS_BAD_GROUP = 5
STATUS_BAD_COUNTS = 6


_PREFETCH = "llvm.prefetch.p0" if llvm_binding.llvm_version_info >= (15,) else "llvm.prefetch.p0i8"


def _prefetch_typing(typingctx: Any, array: Any, index: Any) -> Any:
    """``_prefetch(array, index)``: ask the CPU to fetch the cache line of ``array[index]``.

    A hint, with no effect on results. ``index`` must lie inside the array
    (the address is computed without a check, although a prefetch never faults).
    """
    if not isinstance(array, types.Array) or not isinstance(index, types.Integer):
        return None

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        array_type = signature.args[0]
        data = context.make_array(array_type)(context, builder, args[0])
        pointer = cgutils.get_item_pointer(  # type: ignore[no-untyped-call]
            context, builder, array_type, data, [args[1]], wraparound=False
        )
        byte_pointer = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        function = cgutils.get_or_insert_function(  # type: ignore[no-untyped-call]
            builder.module, ir.FunctionType(ir.VoidType(), [byte_pointer, i32, i32, i32]), _PREFETCH
        )
        # read access, high temporal locality, data cache
        builder.call(function, [builder.bitcast(pointer, byte_pointer), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.void(array, index), codegen


_prefetch: Any = intrinsic(_prefetch_typing)

ARC_DTYPE = np.dtype([("cost", np.float64), ("cls", np.int32), ("edge", np.int32)], align=True)
"""One arc of the reverse class graph: ``edge`` (an edge of the class the arc
leaves), its ``cost``, and ``cls``, the class whose edges have ``edge`` as a
successor. 16 bytes, so the four arcs of a grid junction fill one cache line."""

ArcArray = npt.NDArray[np.void]

_SEARCH_ARCS: weakref.WeakKeyDictionary[EdgeCosts, tuple[EndStateClasses, ArcArray]] = (
    weakref.WeakKeyDictionary()
)


def search_arcs(classes: EndStateClasses, costs: EdgeCosts) -> ArcArray:
    """The arcs of the reverse class graph with the costs of one space, as records.

    Parameters
    ----------
    classes : EndStateClasses
        The network's end-state classes.
    costs : EdgeCosts
        The space's edge costs.

    Returns
    -------
    ArcArray
        ``ARC_DTYPE`` records in the order of ``classes.arc_edge`` (read-only):
        ``cost = costs.cost[arc_edge]``, ``cls = arc_class``, ``edge = arc_edge``.
        Kept as long as ``costs`` lives, so a space builds it once.
    """
    cached = _SEARCH_ARCS.get(costs)
    if cached is not None and cached[0] is classes:
        return cached[1]
    arcs = np.empty(classes.arc_edge.shape[0], dtype=ARC_DTYPE)
    arcs["cost"] = costs.cost[classes.arc_edge]
    arcs["cls"] = classes.arc_class
    arcs["edge"] = classes.arc_edge
    arcs.flags.writeable = False
    _SEARCH_ARCS[costs] = (classes, arcs)
    return arcs


def fleet_columns(positions: Sequence[NetPosition]) -> tuple[IntArray, FloatArray]:
    """Edge indices and offsets of vehicle positions as arrays, not yet checked against a network.

    The common case (every edge index a plain ``int``) is converted directly;
    anything else goes through :func:`routing_svc.network.costs.position_columns`,
    which accepts and rejects exactly the same inputs.

    Raises
    ------
    InvalidInput
        If a position is not a pair of an integer edge index and a number.
    """
    n = len(positions)
    if n:
        try:
            raw_edges, raw_offsets = zip(*positions, strict=True)
            if set(map(type, raw_edges)) == {int}:
                offsets = np.fromiter(raw_offsets, dtype=np.float64, count=n)
                return np.fromiter(raw_edges, dtype=np.int64, count=n), offsets
        except (TypeError, ValueError, OverflowError):
            pass
    return position_columns(positions, what="vehicle")


class SearchBuffers:
    """Preallocated work arrays of the search, reused (and left clean) by every call.

    Parameters
    ----------
    n_nodes : int
        Number of graph nodes (end-state classes).
    n_arcs : int
        Number of graph arcs.

    Notes
    -----
    A buffer set serves one search at a time. The search holds the GIL and
    leaves the arrays clean when it returns, so searches from several threads
    sharing one buffer set run one after another and do not disturb each other.
    """

    def __init__(self, n_nodes: int, n_arcs: int) -> None:
        self.dist = np.full(n_nodes, np.inf)
        self.pred = np.full(n_nodes, -1, dtype=np.int32)
        self.touched = np.empty(n_nodes, dtype=np.int32)
        self.heap_key = np.empty(n_arcs + n_nodes + 1)
        self.heap_node = np.empty(n_arcs + n_nodes + 1, dtype=np.int32)
        self.head = np.full(n_nodes, -1, dtype=np.int32)
        self.next = np.empty(0, dtype=np.int32)

    def nbytes(self) -> int:
        """Bytes held by the work arrays."""
        arrays = (self.dist, self.pred, self.touched, self.heap_key, self.heap_node, self.head)
        return sum(a.nbytes for a in arrays) + self.next.nbytes

    def vehicle_links(self, n_vehicles: int) -> Int32Array:
        """The per-vehicle ``next`` array of the edge -> vehicles lists, grown on demand."""
        if self.next.shape[0] < n_vehicles:
            self.next = np.empty(max(n_vehicles, 2 * self.next.shape[0]), dtype=np.int32)
        return self.next


@njit(cache=True, inline="always")
def _offer(
    slot_start: Int32Array,
    counts: npt.NDArray[np.int64],
    filled: Int32Array,
    best_time: FloatArray,
    best_cost: FloatArray,
    best_idx: Int32Array,
    best_copy: Int32Array,
    g: int,
    time: float,
    cost: float,
    idx: int,
    copy: int,
) -> None:
    """Insert vehicle ``idx`` (reached from its entry ``copy``) into group ``g``'s sorted best
    list if it belongs there; a vehicle appears at most once, with its better entry."""
    k = counts[g]
    base = slot_start[g]
    n = filled[g]
    for j in range(base, base + n):
        if best_idx[j] == idx:
            if time >= best_time[j]:
                return
            for m in range(j, base + n - 1):
                best_time[m] = best_time[m + 1]
                best_cost[m] = best_cost[m + 1]
                best_idx[m] = best_idx[m + 1]
                best_copy[m] = best_copy[m + 1]
            n -= 1
            filled[g] = n
            break
    if n == k:
        last = base + k - 1
        if time > best_time[last] or (time == best_time[last] and idx > best_idx[last]):
            return
        n -= 1
    else:
        filled[g] = n + 1
    j = base + n
    while j > base and (
        best_time[j - 1] > time or (best_time[j - 1] == time and best_idx[j - 1] > idx)
    ):
        best_time[j] = best_time[j - 1]
        best_cost[j] = best_cost[j - 1]
        best_idx[j] = best_idx[j - 1]
        best_copy[j] = best_copy[j - 1]
        j -= 1
    best_time[j] = time
    best_cost[j] = cost
    best_idx[j] = idx
    best_copy[j] = copy


@njit(cache=True, inline="always")
def _prune_key(
    slot_start: Int32Array,
    counts: npt.NDArray[np.int64],
    filled: Int32Array,
    best_time: FloatArray,
    vmax: FloatArray,
) -> float:
    """The largest cost that can still improve some group's best list.

    A group that is not full takes anything (``inf``); a full one only a
    vehicle that arrives no later than its current last, which costs at most
    ``best_time[last] * vmax[g]``. Edges whose key exceeds the largest of
    these bounds need not be pushed.
    """
    bound = 0.0
    for g in range(counts.shape[0]):
        k = counts[g]
        if k <= 0:
            continue
        if filled[g] < k:
            return np.inf
        limit = best_time[slot_start[g] + k - 1] * vmax[g]
        if limit > bound:
            bound = limit
    return bound


@njit(cache=True)
def _check_fleet(
    length: FloatArray,
    veh_edge: npt.NDArray[np.int64],
    veh_offset: FloatArray,
    veh_speed: FloatArray,
    veh_group: npt.NDArray[np.int64],
    counts: npt.NDArray[np.int64],
    vmax: FloatArray,
    available: npt.NDArray[np.int64],
    n_vehicles: int,
) -> tuple[int, int]:
    """Validate the fleet; fill per-group fastest speed and vehicle count.

    Entries from ``n_vehicles`` on are twins (``owner = i - n_vehicles``); a twin
    with edge ``-1`` is absent."""
    n_edges = length.shape[0]
    n_groups = counts.shape[0]
    total = 0
    for g in range(n_groups):
        if counts[g] < 0:
            return STATUS_BAD_COUNTS, g
        total += counts[g]
    if total == 0:
        return STATUS_BAD_COUNTS, -1
    for i in range(veh_edge.shape[0]):
        g = veh_group[i]
        e = veh_edge[i]
        s = veh_offset[i]
        if i >= n_vehicles and e == -1:
            continue
        if e < 0 or e >= n_edges or not (0.0 <= s <= length[e]):
            return STATUS_BAD_POSITION, i % n_vehicles
        if g < -1 or g >= n_groups:
            return STATUS_BAD_GROUP, i
        if g == -1:
            continue
        v = veh_speed[i]
        if not (0.0 < v < np.inf):
            return STATUS_BAD_SPEED, i % n_vehicles
        if i < n_vehicles:
            available[g] += 1
        if v > vmax[g]:
            vmax[g] = v
    for g in range(counts.shape[0]):
        if available[g] < counts[g]:
            return STATUS_UNMET, g
    return STATUS_OK, 0


@njit(cache=True, inline="always")
def _prefetch_node(
    arc_indptr: Int32Array,
    arcs: ArcArray,
    head: Int32Array,
    node: int,
) -> None:
    """Start loading what settling ``node`` will read, as it goes on the heap.

    By the time ``node`` is popped its vehicle list head and its arcs are in
    the cache; without this, each settle waits for two or three cache misses
    in a row (the search is bound by memory latency, not by arithmetic).
    """
    _prefetch(head, node)
    first = arc_indptr[node]
    if first < arcs.shape[0]:
        _prefetch(arcs, first)


@njit(cache=True)
def _route(
    pred: Int32Array, edge_class: Int32Array, start: int, target_edge: int, ahead: bool
) -> npt.NDArray[np.int64]:
    """Edge path from ``start`` to ``target_edge`` along the predecessor pointers.

    ``pred[c]`` is the edge a vehicle at the end of an edge of class ``c``
    takes next. ``ahead``: the vehicle is on the target edge behind the
    target, so the path is that edge alone.
    """
    if start == target_edge and ahead:
        return np.full(1, start, dtype=np.int64)
    length = 2
    cur = pred[edge_class[start]]
    while cur != target_edge and cur >= 0 and length <= edge_class.shape[0] + 1:
        length += 1
        cur = pred[edge_class[cur]]
    route = np.empty(length, dtype=np.int64)
    route[0] = start
    cur = pred[edge_class[start]]
    for j in range(1, length - 1):
        route[j] = cur
        cur = pred[edge_class[cur]]
    route[length - 1] = target_edge
    return route


@njit(cache=True)
def nearest_vehicles(
    arc_indptr: Int32Array,
    arcs: ArcArray,
    edge_class: Int32Array,
    length: FloatArray,
    rate: FloatArray,
    target_edge: int,
    target_offset: float,
    veh_edge: npt.NDArray[np.int64],
    veh_offset: FloatArray,
    veh_speed: FloatArray,
    veh_group: npt.NDArray[np.int64],
    counts: npt.NDArray[np.int64],
    dist: FloatArray,
    pred: Int32Array,
    touched: Int32Array,
    heap_key: FloatArray,
    heap_node: Int32Array,
    head: Int32Array,
    nxt: Int32Array,
    n_vehicles: int,
    cutoff: float,
    probe_edge: npt.NDArray[np.int64] | None = None,
    probe_offset: FloatArray | None = None,
    probe_speed: FloatArray | None = None,
    probe_time: FloatArray | None = None,
    mover_groups: int = -1,
) -> tuple[int, int, int, npt.NDArray[np.int64], FloatArray, FloatArray, Int32Array]:
    """Find the ``counts[g]`` fastest vehicles of every group ``g`` for one target.

    The graph is the reverse end-state class graph
    (:class:`routing_svc.network.layout.EndStateClasses`): ``arc_indptr``
    and ``edge_class``, with the arcs as records that carry the space's
    costs (:func:`search_arcs`). The work arrays ``dist``,
    ``pred`` and ``head`` have one entry per class.

    Returns ``(status, detail, mover_slot, route, best_time, best_cost,
    best_idx)``: on ``STATUS_OK`` the best lists (slots of group ``g`` start
    at ``sum(counts[:g])``, fastest first) hold every served vehicle's time,
    cost and index, ``mover_slot`` is the slot of the vehicle that arrives
    last, and ``route`` holds its edge path to the target. Otherwise
    ``detail`` names the offending vehicle or group. Work arrays are left
    clean.

    Entries ``i >= n_vehicles`` of the vehicle arrays are other ways for
    vehicle ``i - n_vehicles`` to leave (its twin on the reverse edge, or
    edge ``-1`` for none); a vehicle counts once, with its cheaper entry,
    and its route starts at that entry's edge.

    A finite ``cutoff`` (a time) ends the search once no unseen vehicle can
    arrive before it: the best lists then hold what was found (``inf`` and
    ``-1`` in slots left empty, a found vehicle may also arrive later than
    the cutoff), the status is ``STATUS_OK`` and there is no mover or route.

    ``mover_groups >= 0`` chooses the mover among the slots of groups
    ``0 .. mover_groups - 1`` only (``0``: no mover, no route); ``-1``: every group.

    With ``probe_*`` columns (laid out like the vehicles', ``probe_time`` one
    entry per vehicle, speeds no faster than the fastest vehicle's, and one
    group that needs one vehicle), the search also prices those other positions from the
    labels it computed (:func:`_price_probes`): ``probe_time[j]`` is then the
    time of position ``j`` (its better entry) wherever that is less than the
    last served vehicle's arrival, what a second search with that cutoff
    would find.
    """
    n_groups = counts.shape[0]
    n_veh = veh_edge.shape[0]
    vmax = np.zeros(n_groups)
    available = np.zeros(n_groups, dtype=np.int64)
    status, detail = _check_fleet(
        length, veh_edge, veh_offset, veh_speed, veh_group, counts, vmax, available, n_vehicles
    )
    if status != STATUS_OK:
        empty = np.empty(0)
        return status, detail, -1, np.empty(0, dtype=np.int64), empty, empty, np.empty(0, np.int32)
    slot_start = np.zeros(n_groups + 1, dtype=np.int32)
    for g in range(n_groups):
        slot_start[g + 1] = slot_start[g] + counts[g]
    filled = np.zeros(n_groups, dtype=np.int32)
    total = slot_start[n_groups]
    best_time = np.full(total, np.inf)
    best_cost = np.empty(total)
    best_idx = np.full(total, -1, dtype=np.int32)
    best_copy = np.empty(total, dtype=np.int32)

    t_rate = rate[target_edge]
    for i in range(n_veh):
        if veh_edge[i] == target_edge and veh_offset[i] <= target_offset and veh_group[i] >= 0:
            c = (target_offset - veh_offset[i]) * t_rate
            _offer(
                slot_start,
                counts,
                filled,
                best_time,
                best_cost,
                best_idx,
                best_copy,
                veh_group[i],
                c / veh_speed[i],
                c,
                i % n_vehicles,
                i,
            )
    for i in range(n_veh - 1, -1, -1):
        e = veh_edge[i]
        if veh_group[i] >= 0 and e >= 0 and (e != target_edge or veh_offset[i] > target_offset):
            x = edge_class[e]
            nxt[i] = head[x]
            head[x] = i
    reach = cutoff * vmax.max() if n_groups > 0 else np.inf  # no cost beyond it matters
    prune = min(_prune_key(slot_start, counts, filled, best_time, vmax), reach)

    n_touched = 0
    size = 0
    seed = target_offset * t_rate
    t_class = edge_class[target_edge]
    if seed <= prune:
        for a in range(arc_indptr[t_class], arc_indptr[t_class + 1]):
            if arcs[a].edge != target_edge:
                continue
            p = arcs[a].cls
            if dist[p] == np.inf:
                touched[n_touched] = p
                n_touched += 1
            dist[p] = seed
            pred[p] = target_edge
            _prefetch_node(arc_indptr, arcs, head, p)
            size = heap_push(heap_key, heap_node, size, seed, p)

    while size > 0:
        key = heap_key[0]
        x = heap_node[0]
        size = heap_pop(heap_key, heap_node, size)
        if key > dist[x]:
            continue
        if key >= reach:
            break
        done = True
        for g in range(n_groups):
            k = counts[g]
            if k > 0 and (filled[g] < k or best_time[slot_start[g] + k - 1] >= key / vmax[g]):
                done = False
                break
        if done:
            break
        i = head[x]
        while i >= 0:
            e = veh_edge[i]
            c = key + (length[e] - veh_offset[i]) * rate[e]
            _offer(
                slot_start,
                counts,
                filled,
                best_time,
                best_cost,
                best_idx,
                best_copy,
                veh_group[i],
                c / veh_speed[i],
                c,
                i % n_vehicles,
                i,
            )
            i = nxt[i]
            if i < 0:
                prune = min(_prune_key(slot_start, counts, filled, best_time, vmax), reach)
        for a in range(arc_indptr[x], arc_indptr[x + 1]):
            arc = arcs[a]
            through = key + arc.cost
            if through > prune:
                continue
            p = arc.cls
            if through < dist[p]:
                if dist[p] == np.inf:
                    touched[n_touched] = p
                    n_touched += 1
                dist[p] = through
                pred[p] = arc.edge
                _prefetch_node(arc_indptr, arcs, head, p)
                size = heap_push(heap_key, heap_node, size, through, p)

    status = STATUS_OK
    for g in range(n_groups):
        if filled[g] < counts[g] and cutoff == np.inf:
            status = STATUS_UNREACHABLE
            detail = g
            break
    mover_slot = -1
    route = np.empty(0, dtype=np.int64)
    mover_slots = best_time.shape[0] if mover_groups < 0 else slot_start[mover_groups]
    if status == STATUS_OK and mover_slots > 0 and cutoff == np.inf:
        mover_slot = 0
        for j in range(1, mover_slots):
            m = mover_slot
            if best_time[j] > best_time[m] or (
                best_time[j] == best_time[m] and best_idx[j] < best_idx[m]
            ):
                mover_slot = j
        mover = best_copy[mover_slot]
        route = _route(
            pred, edge_class, veh_edge[mover], target_edge, veh_offset[mover] <= target_offset
        )

    if (
        probe_edge is not None
        and probe_offset is not None
        and probe_speed is not None
        and probe_time is not None
    ):
        _price_probes(
            edge_class, length, rate, dist, target_edge, target_offset,
            probe_edge, probe_offset, probe_speed, probe_time,
        )  # fmt: skip
    for j in range(n_touched):
        dist[touched[j]] = np.inf
        pred[touched[j]] = -1
    for i in range(n_veh):
        if veh_edge[i] >= 0:
            head[edge_class[veh_edge[i]]] = -1
    return status, detail, mover_slot, route, best_time, best_cost, best_idx


@njit(cache=True)
def _price_probes(
    edge_class: Int32Array,
    length: FloatArray,
    rate: FloatArray,
    dist: FloatArray,
    target_edge: int,
    target_offset: float,
    probe_edge: npt.NDArray[np.int64],
    probe_offset: FloatArray,
    probe_speed: FloatArray,
    probe_time: FloatArray,
) -> None:
    """Each position's time to the target from the labels ``dist`` a search left (``inf``
    where its class has none); ``probe_time[j]`` gets the better of entries ``j``,
    ``j + n``, ... .

    A label is exact where the search settled its class, and an upper bound
    where it only reached it; the search settled every class whose label is
    below ``T * vmax``, ``T`` the last served vehicle's arrival and ``vmax``
    the fastest speed, so every time below ``T`` is exact, and a position
    whose time is at least ``T`` is not needed. The prices are the search's
    own: ``(s_t - s) * rate[t]`` ahead on the target edge, else the label plus
    the rest of the edge.
    """
    n = probe_time.shape[0]
    t_rate = rate[target_edge]
    for j in range(n):
        probe_time[j] = np.inf
    for i in range(probe_edge.shape[0]):
        e = probe_edge[i]
        if e < 0:
            continue
        s = probe_offset[i]
        if e == target_edge and s <= target_offset:
            c = (target_offset - s) * t_rate
        else:
            label = dist[edge_class[e]]
            if label == np.inf:
                continue
            c = label + (length[e] - s) * rate[e]
        time = c / probe_speed[i]
        j = i % n
        if time < probe_time[j]:
            probe_time[j] = time


@njit(cache=True)
def arrivals_before(
    n_vehicles: int, best_time: FloatArray, best_idx: Int32Array, cutoff: float
) -> FloatArray:
    """Per vehicle, its time in the best lists of :func:`nearest_vehicles` if it is below
    ``cutoff``, else ``inf`` (vehicles that are in no list, or arrive later)."""
    times = np.full(n_vehicles, np.inf)
    for slot in range(best_idx.shape[0]):
        vehicle = best_idx[slot]
        if vehicle >= 0 and best_time[slot] < cutoff:
            times[vehicle] = best_time[slot]
    return times
