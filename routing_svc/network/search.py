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

The search computes ``h`` by Dijkstra on the reverse edge graph, seeded with
``s_t * rate[t]`` at the predecessors of ``t``. Settling edge ``x`` (key
``h[x]``) prices the vehicles on it; no vehicle on an unsettled edge can cost
less than the smallest key on the heap, so for a group whose fastest vehicle
has speed ``v_max`` no unseen vehicle can arrive before ``key / v_max``. The
search stops as soon as every group has its ``count`` best vehicles and the
last of them arrives strictly before that bound, so ties break by the lower
vehicle index exactly as a full search would.

Once every group has its vehicles, an edge whose key would exceed that bound
for every group can no longer matter; such edges are not even put on the
heap.

The predecessor pointers of the same search give the mover's path: ``pred[e]``
is the edge that follows ``e`` on a shortest path to the target.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from routing_svc.network.heap import heap_pop, heap_push

__all__ = [
    "STATUS_BAD_COUNTS",
    "STATUS_BAD_GROUP",
    "STATUS_BAD_POSITION",
    "STATUS_BAD_SPEED",
    "STATUS_OK",
    "STATUS_UNMET",
    "STATUS_UNREACHABLE",
    "SearchBuffers",
    "nearest_vehicles",
]

STATUS_OK = 0
STATUS_UNMET = 1
STATUS_UNREACHABLE = 2
STATUS_BAD_POSITION = 3
STATUS_BAD_SPEED = 4
STATUS_BAD_GROUP = 5
STATUS_BAD_COUNTS = 6

Int32Array = npt.NDArray[np.int32]
FloatArray = npt.NDArray[np.float64]


class SearchBuffers:
    """Preallocated work arrays of the search, reused (and left clean) by every call.

    Parameters
    ----------
    n_edges : int
        Number of graph nodes.
    n_arcs : int
        Number of graph arcs.

    Notes
    -----
    A buffer set serves one search at a time. The search holds the GIL and
    leaves the arrays clean when it returns, so searches from several threads
    sharing one buffer set run one after another and do not disturb each other.
    """

    def __init__(self, n_edges: int, n_arcs: int) -> None:
        self.dist = np.full(n_edges, np.inf)
        self.pred = np.full(n_edges, -1, dtype=np.int32)
        self.touched = np.empty(n_edges, dtype=np.int32)
        self.heap_key = np.empty(n_arcs + n_edges + 1)
        self.heap_node = np.empty(n_arcs + n_edges + 1, dtype=np.int32)
        self.head = np.full(n_edges, -1, dtype=np.int32)
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


@njit(cache=True)
def _route(pred: Int32Array, start: int, target_edge: int, ahead: bool) -> npt.NDArray[np.int64]:
    """Edge path from ``start`` to ``target_edge`` along the predecessor pointers.

    ``ahead``: the vehicle is on the target edge behind the target, so the
    path is that edge alone.
    """
    if start == target_edge and ahead:
        return np.full(1, start, dtype=np.int64)
    length = 2
    cur = pred[start]
    while cur != target_edge and cur >= 0 and length <= pred.shape[0]:
        length += 1
        cur = pred[cur]
    route = np.empty(length, dtype=np.int64)
    route[0] = start
    cur = pred[start]
    for j in range(1, length - 1):
        route[j] = cur
        cur = pred[cur]
    route[length - 1] = target_edge
    return route


@njit(cache=True)
def nearest_vehicles(
    rev_indptr: Int32Array,
    rev_indices: Int32Array,
    length: FloatArray,
    cost: FloatArray,
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
    best_time: FloatArray,
    best_cost: FloatArray,
    best_idx: Int32Array,
    best_copy: Int32Array,
    n_vehicles: int,
) -> tuple[int, int, int, npt.NDArray[np.int64]]:
    """Find the ``counts[g]`` fastest vehicles of every group ``g`` for one target.

    Returns ``(status, detail, mover_slot, route)``: on ``STATUS_OK`` the best
    lists (slots of group ``g`` start at ``sum(counts[:g])``, fastest first)
    are filled, ``mover_slot`` is the slot of the vehicle that arrives last,
    and ``route`` holds its edge path to the target. Otherwise ``detail``
    names the offending vehicle or group. Work arrays are left clean.

    Entries ``i >= n_vehicles`` of the vehicle arrays are other ways for
    vehicle ``i - n_vehicles`` to leave (its twin on the reverse edge, or
    edge ``-1`` for none); a vehicle counts once, with its cheaper entry, and
    ``best_copy`` says which entry that was (the route starts there).
    """
    n_groups = counts.shape[0]
    n_veh = veh_edge.shape[0]
    vmax = np.zeros(n_groups)
    available = np.zeros(n_groups, dtype=np.int64)
    status, detail = _check_fleet(
        length, veh_edge, veh_offset, veh_speed, veh_group, counts, vmax, available, n_vehicles
    )
    if status != STATUS_OK:
        return status, detail, -1, np.empty(0, dtype=np.int64)
    slot_start = np.zeros(n_groups + 1, dtype=np.int32)
    for g in range(n_groups):
        slot_start[g + 1] = slot_start[g] + counts[g]
    filled = np.zeros(n_groups, dtype=np.int32)
    for j in range(best_time.shape[0]):
        best_time[j] = np.inf
        best_idx[j] = -1

    for i in range(n_veh - 1, -1, -1):
        e = veh_edge[i]
        if veh_group[i] >= 0 and e >= 0:
            nxt[i] = head[e]
            head[e] = i
    t_rate = rate[target_edge]
    i = head[target_edge]
    while i >= 0:
        if veh_offset[i] <= target_offset:
            c = (target_offset - veh_offset[i]) * t_rate
            g = veh_group[i]
            _offer(
                slot_start,
                counts,
                filled,
                best_time,
                best_cost,
                best_idx,
                best_copy,
                g,
                c / veh_speed[i],
                c,
                i % n_vehicles,
                i,
            )
        i = nxt[i]
    prune = _prune_key(slot_start, counts, filled, best_time, vmax)

    n_touched = 0
    size = 0
    seed = target_offset * t_rate
    for k in range(rev_indptr[target_edge], rev_indptr[target_edge + 1]):
        p = rev_indices[k]
        if seed < dist[p] and seed <= prune:
            if dist[p] == np.inf:
                touched[n_touched] = p
                n_touched += 1
            dist[p] = seed
            pred[p] = target_edge
            size = heap_push(heap_key, heap_node, size, seed, p)

    while size > 0:
        key = heap_key[0]
        x = heap_node[0]
        size = heap_pop(heap_key, heap_node, size)
        if key > dist[x]:
            continue
        done = True
        for g in range(n_groups):
            k = counts[g]
            if k > 0 and (filled[g] < k or best_time[slot_start[g] + k - 1] >= key / vmax[g]):
                done = False
                break
        if done:
            break
        i = head[x]
        if i >= 0:
            x_rate = rate[x]
            x_len = length[x]
        while i >= 0:
            if x != target_edge or veh_offset[i] > target_offset:
                c = key + (x_len - veh_offset[i]) * x_rate
                g = veh_group[i]
                _offer(
                    slot_start,
                    counts,
                    filled,
                    best_time,
                    best_cost,
                    best_idx,
                    best_copy,
                    g,
                    c / veh_speed[i],
                    c,
                    i % n_vehicles,
                    i,
                )
            i = nxt[i]
            if i < 0:
                prune = _prune_key(slot_start, counts, filled, best_time, vmax)
        through = key + cost[x]
        if through > prune:
            continue
        for k in range(rev_indptr[x], rev_indptr[x + 1]):
            p = rev_indices[k]
            if through < dist[p]:
                if dist[p] == np.inf:
                    touched[n_touched] = p
                    n_touched += 1
                dist[p] = through
                pred[p] = x
                size = heap_push(heap_key, heap_node, size, through, p)

    status = STATUS_OK
    for g in range(n_groups):
        if filled[g] < counts[g]:
            status = STATUS_UNREACHABLE
            detail = g
            break
    mover_slot = -1
    route = np.empty(0, dtype=np.int64)
    if status == STATUS_OK and best_time.shape[0] > 0:
        mover_slot = 0
        for j in range(1, best_time.shape[0]):
            m = mover_slot
            if best_time[j] > best_time[m] or (
                best_time[j] == best_time[m] and best_idx[j] < best_idx[m]
            ):
                mover_slot = j
        mover = best_copy[mover_slot]
        route = _route(pred, veh_edge[mover], target_edge, veh_offset[mover] <= target_offset)

    for j in range(n_touched):
        dist[touched[j]] = np.inf
        pred[touched[j]] = -1
    for i in range(n_veh):
        if veh_edge[i] >= 0:
            head[veh_edge[i]] = -1
    return status, detail, mover_slot, route
