"""The optimum of a heterogeneous fleet: vehicle types, speeds and requirement mixes.

Vehicle ``i`` has a type ``t_i`` and a speed factor ``v_i``; from position
``p_i`` it reaches demand atom ``z_j`` after ``tau_ij = D(p_i, z_j) / v_i``. A
target of requirement class ``r`` needs a multiset of types (``("A", "B")``:
one A and one B; ``("A", "A")``: two A's; ``()``: any one vehicle) and is
served when the last required vehicle arrives:

.. math:: T_{rj} = \\max_t \\; \\tau^{(m_{rt})}_{tj},

with ``tau^(m)_tj`` the ``m``-th smallest time to ``z_j`` among vehicles of type
``t`` and ``m_rt`` how many of them class ``r`` needs. Objective (11) of Le Ny &
Pappas, generalised to any mix of classes with shares ``s_r`` (normalised to sum
to 1) and service cost ``c(T) = T**q``, is

.. math:: J(p) = \\sum_r s_r \\sum_j w_j \\, T_{rj}^q.

:func:`heterogeneous_cost` evaluates it exactly; :func:`solve_heterogeneous`
places one vehicle on a candidate site each (several may share a site) to
minimise it:

- ``"milp"``: exact, the model of :mod:`routing_svc.optimum.heterogeneous_milp`
  (HiGHS). ``method="auto"`` uses it up to :data:`MILP_MAX_SITES` distinct
  sites, :data:`MILP_MAX_VEHICLES` vehicles and :data:`MILP_MAX_PAIRS`
  site-atom pairs (a few seconds on such instances; its LP bound is weak, so
  the time grows fast beyond), after the heuristic, keeping the better.
- ``"heuristic"``: every type starts at the p-median
  (:func:`routing_svc.optimum.pmedian.solve_pmedian`) of the demand that needs
  it, then a deterministic best-improvement local search on the exact ``J``:
  relocate one vehicle to any site (every site priced in one compiled pass: with
  the others fixed, the ``m``-th smallest time of a group is
  ``min(max(tau, o_(m-1)), o_m)`` of the others' order statistics), and when
  no relocation gains, swap the sites of two vehicles of different kinds.

When every class needs any one vehicle and all speeds are equal, ``J`` is the
p-median objective (types do not matter) and the solver is
:func:`solve_pmedian` itself.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, TypeVar

import numpy as np
from numba import njit

from routing_svc.demand import DemandDistribution
from routing_svc.errors import InvalidInput, UnmetRequirement, Unreachable
from routing_svc.optimum.candidates import distinct_rows
from routing_svc.optimum.evaluate import CostModel
from routing_svc.optimum.heterogeneous_milp import CompiledClass, solve_milp
from routing_svc.optimum.pmedian import PROVEN_GAP, checked_costs, solve_pmedian
from routing_svc.sa.requirements import build_requirement
from routing_svc.sa.space import Requirement
from routing_svc.types import FloatArray, IntArray, NetPosition, PlanePosition

Method = Literal["auto", "milp", "heuristic"]
P = TypeVar("P", NetPosition, PlanePosition)

#: ``method="auto"`` is exact up to this many distinct candidate sites ...
MILP_MAX_SITES = 60
#: ... this many vehicles ...
MILP_MAX_VEHICLES = 6
#: ... and this many (distinct site, demand atom with a positive weight) pairs.
MILP_MAX_PAIRS = 240

#: A local-search move must lower ``J`` by more than this fraction.
MOVE_TOLERANCE = 1e-12


@dataclass(frozen=True, slots=True)
class RequirementClass:
    """One class of targets: the multiset of types it needs and its share of the demand.

    ``requires = ()`` means any one vehicle of the fleet.
    """

    requires: tuple[str, ...] = ()
    share: float = 1.0


#: The default mix: every target needs any one vehicle.
ANY_ONE: tuple[RequirementClass, ...] = (RequirementClass(),)


@dataclass(frozen=True, slots=True)
class HeterogeneousSolution:
    """One candidate site per vehicle and the objective ``J`` it achieves.

    Attributes
    ----------
    sites : tuple of int
        Row of the cost matrix where each vehicle stands, in vehicle order.
    objective : float
        ``J`` of these sites, recomputed exactly from the distances.
    method : str
        ``"milp"`` or ``"heuristic"``.
    proven_optimal : bool
        True when ``objective`` is proven optimal within a relative ``1e-9``.
    seconds : float
        Wall-clock time of the solve.
    lower_bound : float or None
        Exact method: a proven lower bound on the optimum; ``None`` otherwise.
    """

    sites: tuple[int, ...]
    objective: float
    method: str
    proven_optimal: bool
    seconds: float
    lower_bound: float | None = None


def requirement_mix(
    items: Sequence[RequirementClass] | None, vehicle_types: Sequence[str]
) -> tuple[RequirementClass, ...]:
    """Check a mix against the fleet and normalise its shares to sum to 1.

    Raises
    ------
    InvalidInput
        An empty mix, or a share that is not finite and ``> 0``.
    UnmetRequirement
        A class needs a type the fleet lacks, or more of it than the fleet has.
    """
    mix = ANY_ONE if items is None else tuple(items)
    if not mix:
        raise InvalidInput("a requirement mix needs at least one class")
    for k, item in enumerate(mix):
        share = item.share
        if isinstance(share, bool) or not math.isfinite(share) or share <= 0.0:
            raise InvalidInput(f"requirement class {k}: share must be finite and > 0, got {share}")
        try:
            build_requirement(vehicle_types, item.requires)
        except UnmetRequirement as error:
            raise UnmetRequirement(f"requirement class {k}: {error.detail}") from None
    total = math.fsum(item.share for item in mix)
    return tuple(RequirementClass(tuple(i.requires), i.share / total) for i in mix)


def is_heterogeneous(
    vehicle_types: Sequence[str],
    speeds: Sequence[float] | FloatArray,
    items: Sequence[RequirementClass] | None,
) -> bool:
    """Whether the fleet or the mix goes beyond "identical vehicles, any one serves"."""
    return (
        len(set(vehicle_types)) > 1
        or len({float(v) for v in speeds}) > 1
        or (items is not None and any(item.requires for item in items))
    )


def heterogeneous_cost_from_times(
    times: FloatArray,
    vehicle_types: Sequence[str],
    weights: FloatArray,
    mix: Sequence[RequirementClass] | None = None,
    *,
    power: float = 1.0,
) -> float:
    """``J = sum_r s_r sum_j w_j T_rj**q`` (objective (11)) from a vehicles-by-atoms time matrix.

    Parameters
    ----------
    times : FloatArray
        ``tau_ij = D(p_i, z_j) / v_i``, shape ``(n_vehicles, n_atoms)``.
    vehicle_types : sequence of str
        Type of every vehicle (row).
    weights : FloatArray
        ``w_j >= 0``, one per atom.
    mix : sequence of RequirementClass, optional
        Requirement classes and shares (normalised here); default any one vehicle.
    power : float
        Exponent ``q > 0`` of ``c(T) = T**q``.

    Raises
    ------
    InvalidInput
        Shapes that do not match, negative or NaN times or weights, a bad power or mix.
    UnmetRequirement
        A class the fleet cannot serve.
    Unreachable
        An atom with a positive weight whose completion time is infinite.
    """
    t = np.asarray(times, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    if not math.isfinite(power) or power <= 0.0:
        raise InvalidInput(f"power must be a finite number > 0, got {power!r}")
    if t.ndim != 2 or t.shape[0] != len(vehicle_types) or w.shape != (t.shape[1],):
        raise InvalidInput(
            f"times of shape {t.shape} do not match {len(vehicle_types)} vehicles "
            f"and {w.shape[0] if w.ndim == 1 else w.shape} atoms"
        )
    if np.any(np.isnan(t)) or np.any(t < 0.0) or not np.all(np.isfinite(w)) or np.any(w < 0.0):
        raise InvalidInput("times and weights must be non-negative numbers")
    classes = _compile(requirement_mix(mix, vehicle_types), vehicle_types)
    completion = _completion(t, classes)
    bad = np.flatnonzero(~np.all(np.isfinite(completion), axis=0) & (w > 0))
    if bad.size:
        raise Unreachable(f"demand atom {int(bad[0])} cannot be served ({bad.size} such atoms)")
    keep = w > 0
    terms = (np.array([c.share for c in classes])[:, None] * w[keep]) * completion[:, keep] ** power
    return math.fsum(terms.ravel().tolist())


def heterogeneous_cost(
    model: CostModel[P],
    positions: Sequence[P],
    vehicle_types: Sequence[str],
    speeds: Sequence[float] | FloatArray,
    demand: DemandDistribution[P],
    mix: Sequence[RequirementClass] | None = None,
    *,
    power: float = 1.0,
) -> float:
    """Exact ``J`` of vehicle positions: distances from ``model.cost_matrix``, then
    :func:`heterogeneous_cost_from_times` on ``D(p_i, z_j) / v_i``."""
    v = np.asarray(speeds, dtype=np.float64)
    if not positions or v.shape != (len(positions),):
        raise InvalidInput(f"need one speed per vehicle (and a vehicle), got {v.shape}")
    if not np.all(np.isfinite(v)) or np.any(v <= 0.0):
        raise InvalidInput("speeds must be finite and > 0")
    d = np.asarray(model.cost_matrix(list(positions), list(demand.positions)), dtype=np.float64)
    if d.shape != (len(positions), len(demand.positions)):
        raise InvalidInput(f"cost model returned shape {d.shape}")
    return heterogeneous_cost_from_times(
        d / v[:, None], vehicle_types, np.asarray(demand.weights), mix, power=power
    )


def solve_heterogeneous(
    costs: FloatArray,
    weights: FloatArray,
    vehicle_types: Sequence[str],
    speeds: Sequence[float] | FloatArray,
    mix: Sequence[RequirementClass] | None = None,
    *,
    power: float = 1.0,
    method: Method = "auto",
    time_limit: float = 60.0,
) -> HeterogeneousSolution:
    """Choose a candidate site for every vehicle minimising ``J`` (objective (11)).

    Parameters
    ----------
    costs : FloatArray
        Distances ``D(s, z_j) >= 0``, finite, shape ``(n_sites, n_atoms)`` (not
        raised to ``power``, not divided by speeds).
    weights : FloatArray
        ``w_j >= 0`` with a positive sum.
    vehicle_types, speeds : sequences
        Type and speed factor ``v_i > 0`` of every vehicle.
    mix : sequence of RequirementClass, optional
        Requirement classes with shares; default any one vehicle.
    power : float
        Exponent ``q`` of ``c(T) = T**q``.
    method : {"auto", "milp", "heuristic"}
        ``"auto"``: the MILP within the module's size limits, else the heuristic.
    time_limit : float
        Seconds allowed to the MILP (then its best solution, not proven) and to
        the local search (which is deterministic unless this cuts it short).

    Raises
    ------
    InvalidInput
        Bad shapes or values, an unknown method, a bad mix.
    UnmetRequirement
        A class the fleet cannot serve.
    """
    started = time.perf_counter()
    d, w, v = _validated(costs, weights, vehicle_types, speeds, power)
    if method not in ("auto", "milp", "heuristic"):
        raise InvalidInput(f"method must be 'auto', 'milp' or 'heuristic', got {method!r}")
    if not math.isfinite(time_limit) or time_limit <= 0:
        raise InvalidInput(f"time_limit must be a finite number > 0, got {time_limit!r}")
    mix = requirement_mix(mix, vehicle_types)
    classes = _compile(mix, vehicle_types)
    deadline = started + time_limit
    rows = distinct_rows(d)
    if all(not c.requires for c in mix) and np.all(v == v[0]):  # exactly the p-median
        pm = solve_pmedian((d / v[0]) ** power, w, min(len(v), len(d)), time_limit=time_limit)
        chosen = np.resize(np.array(pm.sites, dtype=np.int64), len(v))
        value = _value(d, w, v, classes, power, chosen)
        return _solution(chosen, value, pm.method, started, pm.lower_bound)
    exact = method == "milp" or (
        method == "auto"
        and len(rows) <= MILP_MAX_SITES
        and len(v) <= MILP_MAX_VEHICLES
        and len(rows) * w.size <= MILP_MAX_PAIRS
    )
    sub = d[rows]
    kind_of = _kinds(vehicle_types, v)
    start = _start(sub, w, vehicle_types, mix, power)
    local = _local_search(sub, w, v, classes, power, start, kind_of, deadline)
    value, lower = _value(sub, w, v, classes, power, local), None
    if exact:
        found, lower = solve_milp(sub, w, v, kind_of, classes, power, deadline=deadline)
        if found is not None and (exact_value := _value(sub, w, v, classes, power, found)) < value:
            local, value = found, exact_value
    return _solution(rows[local], value, "milp" if exact else "heuristic", started, lower)


def heterogeneous_optimum(
    model: CostModel[P],
    sites: Sequence[P],
    demand: DemandDistribution[P],
    vehicle_types: Sequence[str],
    speeds: Sequence[float] | FloatArray,
    mix: Sequence[RequirementClass] | None = None,
    *,
    power: float = 1.0,
    time_limit: float = 60.0,
) -> tuple[list[P], HeterogeneousSolution]:
    """Candidate sites to distances to :func:`solve_heterogeneous`: the position of
    every vehicle at the optimum of objective (11), and the solution."""
    d = model.cost_matrix(list(sites), list(demand.positions))
    solution = solve_heterogeneous(
        d,
        np.asarray(demand.weights),
        vehicle_types,
        speeds,
        mix,
        power=power,
        time_limit=time_limit,
    )
    return [sites[i] for i in solution.sites], solution


# -- internals ---------------------------------------------------------------------------


def _validated(
    costs: FloatArray,
    weights: FloatArray,
    vehicle_types: Sequence[str],
    speeds: Sequence[float] | FloatArray,
    power: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Distances and weights of the atoms with ``w_j > 0``, and the speeds."""
    d, w = checked_costs(costs, weights)
    v = np.asarray(speeds, dtype=np.float64)
    if len(vehicle_types) == 0 or v.shape != (len(vehicle_types),):
        raise InvalidInput(f"need one speed per vehicle (and a vehicle), got {v.shape}")
    if not np.all(np.isfinite(v)) or np.any(v <= 0.0):
        raise InvalidInput("speeds must be finite and > 0")
    if isinstance(power, bool) or not math.isfinite(power) or power <= 0.0:
        raise InvalidInput(f"power must be a finite number > 0, got {power!r}")
    keep = w > 0
    return np.ascontiguousarray(d[:, keep]), w[keep], v


def _compile(mix: Sequence[RequirementClass], vehicle_types: Sequence[str]) -> list[CompiledClass]:
    """Vehicle index groups of every class (from :func:`build_requirement`)."""
    out = []
    for item in mix:
        req: Requirement = build_requirement(vehicle_types, item.requires)[0]
        groups = tuple(
            (np.flatnonzero(req.vehicle_groups == g).astype(np.int64), int(m))
            for g, m in enumerate(req.counts)
        )
        out.append(CompiledClass(item.share, groups))
    return out


def _completion(times: FloatArray, classes: Sequence[CompiledClass]) -> FloatArray:
    """``T_rj``, shape ``(n_classes, n_atoms)``: max over groups of the m-th smallest time."""
    out = np.empty((len(classes), times.shape[1]))
    for r, cls in enumerate(classes):
        kth = [np.partition(times[idx], m - 1, axis=0)[m - 1] for idx, m in cls.groups]
        out[r] = np.max(kth, axis=0)
    return out


def _value(
    d: FloatArray,
    w: FloatArray,
    v: FloatArray,
    classes: Sequence[CompiledClass],
    q: float,
    at: IntArray,
) -> float:
    """``J`` of vehicles at rows ``at`` of ``d``."""
    completion = _completion(d[at] / v[:, None], classes) ** q
    shares = np.array([c.share for c in classes])
    return math.fsum(((shares[:, None] * w) * completion).ravel().tolist())


def _solution(
    sites: IntArray, value: float, method: str, started: float, lower: float | None
) -> HeterogeneousSolution:
    if lower is not None and not math.isfinite(lower):
        lower = None
    return HeterogeneousSolution(
        sites=tuple(int(s) for s in sites),
        objective=value,
        method=method,
        proven_optimal=lower is not None and value - lower <= PROVEN_GAP * value,
        seconds=time.perf_counter() - started,
        lower_bound=None if lower is None else min(lower, value),
    )


def _kinds(vehicle_types: Sequence[str], v: FloatArray) -> IntArray:
    """Every vehicle's kind: the rank of its (type, speed) among the distinct pairs."""
    keys = sorted({(t, float(s)) for t, s in zip(vehicle_types, v, strict=True)})
    code = {key: k for k, key in enumerate(keys)}
    return np.array(
        [code[(t, float(s))] for t, s in zip(vehicle_types, v, strict=True)], dtype=np.int64
    )


def _start(
    d: FloatArray,
    w: FloatArray,
    vehicle_types: Sequence[str],
    mix: Sequence[RequirementClass],
    q: float,
) -> IntArray:
    """Every type at the p-median of the demand that needs it (any-one classes by fleet share)."""
    n = len(vehicle_types)
    sites = np.empty(n, dtype=np.int64)
    powered = d**q
    for t in sorted(set(vehicle_types)):
        mine = np.flatnonzero(np.array([x == t for x in vehicle_types]))
        share = sum(c.share for c in mix if t in c.requires)
        share += sum(c.share * mine.size / n for c in mix if not c.requires)
        demand = w * share if share > 0 else w
        pm = solve_pmedian(powered, demand, min(mine.size, d.shape[0]), method="heuristic")
        sites[mine] = np.resize(np.array(pm.sites, dtype=np.int64), mine.size)
    return sites


def _local_search(
    d: FloatArray,
    w: FloatArray,
    v: FloatArray,
    classes: Sequence[CompiledClass],
    q: float,
    at: IntArray,
    kind_of: IntArray,
    deadline: float,
) -> IntArray:
    """Best-improvement relocations, then swaps between kinds, until neither gains."""
    at = at.copy()
    current = _value(d, w, v, classes, q, at)
    while time.perf_counter() < deadline:
        vehicle, site, value = _best_relocation(d, w, v, classes, q, at)
        if value < current * (1 - MOVE_TOLERANCE):
            at[vehicle] = site
            current = _value(d, w, v, classes, q, at)
            continue
        swapped, value = _best_swap(d, w, v, classes, q, at, kind_of)
        if swapped is None or not value < current * (1 - MOVE_TOLERANCE):
            break
        at, current = swapped, value
    return at


def _best_relocation(
    d: FloatArray,
    w: FloatArray,
    v: FloatArray,
    classes: Sequence[CompiledClass],
    q: float,
    at: IntArray,
) -> tuple[int, int, float]:
    """The single-vehicle move to any site with the lowest ``J``: (vehicle, site, J)."""
    times = d[at] / v[:, None]
    best = (0, int(at[0]), math.inf)
    for i in range(len(at)):
        totals = np.zeros(d.shape[0])
        for cls in classes:
            fixed = np.zeros(d.shape[1])
            order: tuple[FloatArray, FloatArray] | None = None
            for idx, m in cls.groups:
                if i in idx:
                    others = np.sort(times[idx[idx != i]], axis=0)
                    lo = others[m - 2] if m >= 2 else np.full(d.shape[1], -np.inf)
                    hi = others[m - 1] if others.shape[0] >= m else np.full(d.shape[1], np.inf)
                    order = (lo, hi)
                else:
                    fixed = np.maximum(fixed, np.partition(times[idx], m - 1, axis=0)[m - 1])
            if order is None:
                totals += cls.share * float(w @ fixed**q)
                continue
            _add_relocated(totals, d, w, v[i], order[0], order[1], fixed, q, cls.share)
        site = int(np.argmin(totals))
        if totals[site] < best[2]:
            best = (i, site, float(totals[site]))
    return best


@njit(cache=True)
def _add_relocated(
    totals: FloatArray,
    d: FloatArray,
    w: FloatArray,
    speed: float,
    lo: FloatArray,
    hi: FloatArray,
    fixed: FloatArray,
    q: float,
    share: float,
) -> None:
    """Add to ``totals[s]`` one class's ``share * sum_j w_j T_j**q`` with the relocated
    vehicle at site ``s``: ``T_j = max(min(max(d[s, j] / speed, lo_j), hi_j), fixed_j)``,
    its group's ``m``-th smallest time given the others' order statistics ``lo, hi`` and
    the other groups' ``fixed`` (objective (11))."""
    for s in range(d.shape[0]):
        acc = 0.0
        for j in range(d.shape[1]):
            t = max(min(max(d[s, j] / speed, lo[j]), hi[j]), fixed[j])
            if q == 1.0:
                acc += w[j] * t
            elif q == 2.0:
                acc += w[j] * (t * t)
            else:
                acc += w[j] * t**q
        totals[s] += share * acc


def _best_swap(
    d: FloatArray,
    w: FloatArray,
    v: FloatArray,
    classes: Sequence[CompiledClass],
    q: float,
    at: IntArray,
    kind_of: IntArray,
) -> tuple[IntArray | None, float]:
    """The exchange of two vehicles' sites (of different kinds) with the lowest ``J``."""
    best: tuple[IntArray | None, float] = (None, math.inf)
    for i in range(len(at)):
        for k in range(i + 1, len(at)):
            if at[i] == at[k] or kind_of[i] == kind_of[k]:
                continue
            trial = at.copy()
            trial[i], trial[k] = at[k], at[i]
            value = _value(d, w, v, classes, q, trial)
            if value < best[1]:
                best = (trial, value)
    return best
