"""The exact model of the heterogeneous optimum (objective (11) of Le Ny & Pappas).

Vehicles of one type and speed (a *kind* ``k`` with ``n_k`` vehicles) are
interchangeable, so the integer ``y_ks`` in ``{0..n_k}`` counts those at site
``s`` (for ``n_k = 1`` it is the vehicle-at-site binary), ``sum_s y_ks = n_k``.
With ``tau_ksj = (D(s, z_j) / v_k)**q``, every requirement class ``r``, required
type ``t`` (``"any one"`` counts as one group of all vehicles), slot
``l < m_rt`` and atom ``j`` assigns one vehicle of that type::

    min  sum_r s_r sum_j w_j T_rj
    s.t. sum_s y_ks = n_k                               for every kind k
         sum_{k of t, s} x_rtljks = 1                   one vehicle per slot
         sum_l x_rtljks <= y_ks                         slots take distinct vehicles
         T_rj >= sum_{k, s} tau_ksj x_rtljks             the last arrival of every slot
         sum_ks tau_ksj x_rtljks <= sum_ks tau_ksj x_rt(l+1)jks   (slots ordered)

so ``T_rj`` is at least the ``m_rt``-th smallest time of every required type,
and at the optimum equal to the largest of them. ``x`` is binary when
``m_rt >= 2`` (fractional slots would average their times) and continuous for a
single slot (given integer ``y`` it then picks the fastest vehicle). Times are
scaled by their maximum and weights by their sum for HiGHS.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.optimize import Bounds, LinearConstraint, milp

from routing_svc.types import FloatArray, IntArray

#: HiGHS's relative MIP gap (well under the 1e-9 that counts as proven).
MIP_REL_GAP = 1e-10


@dataclass(frozen=True, slots=True)
class CompiledClass:
    """A requirement class against one fleet: its share and, per required type,
    the indices of the vehicles of that type and how many of them it needs."""

    share: float
    groups: tuple[tuple[IntArray, int], ...]


class _Rows:
    """Sparse constraint rows ``lo <= A x <= hi`` collected block by block."""

    def __init__(self) -> None:
        self.count = 0
        self.rows: list[IntArray] = []
        self.cols: list[IntArray] = []
        self.vals: list[FloatArray] = []
        self.lo: list[FloatArray] = []
        self.hi: list[FloatArray] = []

    def add(self, rows: IntArray, cols: IntArray, vals: FloatArray, lo: float, hi: float) -> None:
        """Rows ``0..max(rows)`` of a block (numbered from 0), all with bounds ``lo, hi``."""
        n = int(rows.max()) + 1
        self.rows.append(self.count + rows)
        self.cols.append(cols)
        self.vals.append(vals)
        self.lo.append(np.full(n, lo))
        self.hi.append(np.full(n, hi))
        self.count += n

    def constraint(self, n_var: int) -> LinearConstraint:
        matrix = sp.csr_array(
            (np.concatenate(self.vals), (np.concatenate(self.rows), np.concatenate(self.cols))),
            shape=(self.count, n_var),
        )
        return LinearConstraint(matrix, np.concatenate(self.lo), np.concatenate(self.hi))


def solve_milp(
    d: FloatArray,
    w: FloatArray,
    v: FloatArray,
    kind_of: IntArray,
    classes: Sequence[CompiledClass],
    q: float,
    *,
    deadline: float,
) -> tuple[IntArray | None, float]:
    """Solve the model of the module docstring with HiGHS until ``deadline``.

    Parameters
    ----------
    d : FloatArray
        Distances ``D(s, z_j)``, shape ``(n_sites, n_atoms)``.
    w : FloatArray
        Positive weights of the atoms.
    v : FloatArray
        Speed of every vehicle.
    kind_of : IntArray
        Kind ``0..K-1`` of every vehicle (one type and one speed per kind).
    classes : sequence of CompiledClass
        The requirement classes (shares summing to 1).
    q : float
        Power of the service cost.
    deadline : float
        ``time.perf_counter()`` value after which HiGHS stops.

    Returns
    -------
    (IntArray or None, float)
        The site of every vehicle in the best solution found (``None`` if
        none), and a proven lower bound on the optimal ``J`` (``-inf`` if none).
    """
    n_sites, n_atoms = d.shape
    n_kinds = int(kind_of.max()) + 1
    counts = np.bincount(kind_of, minlength=n_kinds).astype(np.float64)
    speed = np.array([v[np.flatnonzero(kind_of == k)[0]] for k in range(n_kinds)])
    tau = (d[None, :, :] / speed[:, None, None]) ** q  # (kind, site, atom)
    scale = float(tau.max()) or 1.0
    tau = tau / scale
    n_y = n_kinds * n_sites
    atoms = np.arange(n_atoms)
    rows = _Rows()
    rows.add(np.repeat(np.arange(n_kinds), n_sites), np.arange(n_y), np.ones(n_y), 0.0, 0.0)
    rows.lo[-1] = rows.hi[-1] = counts  # sum_s y_ks = n_k
    integrality, upper = [np.ones(n_y)], [np.repeat(counts, n_sites)]
    first = n_y
    first_t = n_y + sum(
        m * n_atoms * np.unique(kind_of[idx]).size * n_sites for c in classes for idx, m in c.groups
    )
    for r, cls in enumerate(classes):
        t_cols = first_t + r * n_atoms + atoms
        for idx, m in cls.groups:
            kinds = np.unique(kind_of[idx])
            width = kinds.size * n_sites  # one atom's (kind, site) pairs
            size = n_atoms * width
            per_atom = np.repeat(atoms, width)
            coef = tau[kinds].transpose(2, 0, 1).reshape(-1)  # tau[k, s, j] at x[j, k, s]
            slots = [first + slot * size + np.arange(size) for slot in range(m)]
            first += m * size
            integrality.append(np.full(m * size, 1.0 if m >= 2 else 0.0))
            upper.append(np.ones(m * size))
            for cols in slots:
                rows.add(per_atom, cols, np.ones(size), 1.0, 1.0)  # one vehicle per slot
                rows.add(  # T_rj >= the slot's time
                    np.concatenate([per_atom, atoms]),
                    np.concatenate([cols, t_cols]),
                    np.concatenate([coef, -np.ones(n_atoms)]),
                    -np.inf,
                    0.0,
                )
            y_cols = np.tile((kinds[:, None] * n_sites + np.arange(n_sites)).ravel(), n_atoms)
            pair = np.arange(size)
            rows.add(  # distinct vehicles: sum_l x_l <= y
                np.tile(pair, m + 1),
                np.concatenate([*slots, y_cols]),
                np.concatenate([np.ones(m * size), -np.ones(size)]),
                -np.inf,
                0.0,
            )
            for a, b in itertools.pairwise(slots):  # ordered slot times
                rows.add(
                    np.tile(per_atom, 2), np.concatenate([a, b]), np.concatenate([coef, -coef]),
                    -np.inf, 0.0,
                )  # fmt: skip
    n_var = first_t + len(classes) * n_atoms
    integrality.append(np.zeros(len(classes) * n_atoms))
    upper.append(np.full(len(classes) * n_atoms, np.inf))
    objective = np.zeros(n_var)
    shares = np.array([c.share for c in classes])
    objective[first_t:] = (shares[:, None] * (w / w.sum())).ravel()
    remaining = deadline - time.perf_counter()
    if remaining <= 0:
        return None, -math.inf
    result = milp(
        objective,
        constraints=[rows.constraint(n_var)],
        integrality=np.concatenate(integrality),
        bounds=Bounds(np.zeros(n_var), np.concatenate(upper)),
        options={"time_limit": remaining, "mip_rel_gap": MIP_REL_GAP, "disp": False},
    )
    unit = scale * float(w.sum())
    bound = result.get("mip_dual_bound")
    lower = float(bound) * unit if bound is not None and math.isfinite(bound) else -math.inf
    if result.status == 0 and result.fun is not None:
        lower = max(lower, float(result.fun) * unit * (1.0 - MIP_REL_GAP))
    if result.x is None:
        return None, lower
    y = np.rint(result.x[:n_y]).astype(np.int64).reshape(n_kinds, n_sites)
    if not np.array_equal(y.sum(axis=1), counts.astype(np.int64)) or np.any(y < 0):
        return None, lower
    sites = np.empty(len(v), dtype=np.int64)
    for k in range(n_kinds):
        sites[kind_of == k] = np.repeat(np.arange(n_sites), y[k])
    return sites, lower
