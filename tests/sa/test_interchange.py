"""The compiled greedy addition and fast interchange against plain numpy references.

The references are the vectorised numpy forms the package used before its numba
kernels (every site priced every round; every swap priced as an ``(n, p)``
matrix). They are also the named baseline of ``bench/consolidation.py``.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import scipy.sparse as sp

from routing_svc.sa.interchange import SWAP_TOLERANCE, fast_interchange, greedy
from routing_svc.sa.interchange_kernels import (
    fill_gains,
    fill_losses,
    gain_of,
    nearest_two,
    swap_losses,
)
from routing_svc.types import BoolArray, FloatArray, IntArray

BLOCK_ROWS = 256


def reference_greedy(c: FloatArray, w: FloatArray, p: int) -> IntArray:
    """Greedy addition pricing every site every round (lowest index among equal ``F``)."""
    n = c.shape[0]
    best = np.full(c.shape[1], np.inf)
    is_open = np.zeros(n, dtype=bool)
    for _ in range(p):
        totals = np.empty(n)
        for lo in range(0, n, BLOCK_ROWS):
            totals[lo : lo + BLOCK_ROWS] = np.minimum(c[lo : lo + BLOCK_ROWS], best) @ w
        totals[is_open] = np.inf
        pick = int(np.argmin(totals))
        is_open[pick] = True
        best = np.minimum(best, c[pick])
    return np.flatnonzero(is_open).astype(np.int64)


def reference_fast_interchange(c: FloatArray, w: FloatArray, sites: IntArray) -> IntArray:
    """Whitaker's fast interchange with the ``(n, p)`` matrix of swap changes."""
    n = c.shape[0]
    open_sites = np.array(sites, dtype=np.int64)
    p = open_sites.size
    current = _value(c, w, open_sites)
    while True:
        c1, c2, owner = reference_nearest(c, w, open_sites)
        delta = np.empty((n, p))
        for lo in range(0, n, BLOCK_ROWS):
            block = c[lo : lo + BLOCK_ROWS]
            gain = np.minimum(block - c1, 0.0) @ w
            fallback = np.maximum(np.minimum(block, c2) - c1, 0.0)
            delta[lo : lo + BLOCK_ROWS] = gain[:, None] + (owner @ fallback.T).T
        delta[open_sites] = np.inf
        enter, leave = divmod(int(np.argmin(delta)), p)
        if not delta[enter, leave] < -SWAP_TOLERANCE * current:
            return open_sites
        candidate = open_sites.copy()
        candidate[leave] = enter
        value = _value(c, w, candidate)
        if not value < current:
            return open_sites
        open_sites, current = candidate, value


def _value(c: FloatArray, w: FloatArray, sites: IntArray) -> float:
    return math.fsum((w * c[sites].min(axis=0)).tolist())


def brute_force_greedy(c: FloatArray, w: FloatArray, p: int) -> list[int]:
    """Greedy addition by the definition: ``F`` of every ``S + i`` summed exactly."""
    chosen: list[int] = []
    for _ in range(p):
        values = [
            (_value(c, w, np.array([*chosen, i])), i) for i in range(c.shape[0]) if i not in chosen
        ]
        chosen.append(min(values)[1])
    return sorted(chosen)


def instance(seed: int, *, integer: bool, zero_weights: bool) -> tuple[FloatArray, FloatArray, int]:
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(2, 40)), int(rng.integers(1, 70))
    p = int(rng.integers(1, min(n, 9) + 1))
    if integer:
        c = rng.integers(0, 6, size=(n, m)).astype(np.float64)
        w = rng.integers(0, 4, size=m).astype(np.float64)
    else:
        c = rng.exponential(size=(n, m)) ** 2
        w = rng.uniform(0.1, 3.0, size=m)
    if zero_weights:
        w[rng.random(m) < 0.5] = 0.0
    return c, w, p


KINDS = [(False, False), (False, True), (True, False), (True, True)]


@pytest.mark.parametrize(("integer", "zero_weights"), KINDS)
def test_lazy_greedy_opens_the_sites_of_plain_greedy(integer: bool, zero_weights: bool) -> None:
    for seed in range(150):
        c, w, p = instance(seed, integer=integer, zero_weights=zero_weights)
        expected = reference_greedy(c, w, p)
        assert greedy(c, w, p).tolist() == expected.tolist(), seed


def test_greedy_breaks_ties_by_the_lowest_index() -> None:
    """Sites 1, 2 and 3 serve the same atoms; after site 0 each lowers ``F`` by 4."""
    c = np.array([[0.0, 0.0, 9.0, 9.0], [9, 9, 1, 1], [9, 9, 1, 1], [9, 9, 1, 1]])
    w = np.array([5.0, 5.0, 2.0, 2.0])
    assert greedy(c, w, 2).tolist() == [0, 1]
    assert greedy(c[::-1], w, 2).tolist() == [0, 3]
    # with every weight zero every F is 0: the lowest indices open
    assert greedy(c, np.zeros(4), 3).tolist() == [0, 1, 2]


def test_greedy_matches_the_definition_on_integer_costs() -> None:
    for seed in range(60):
        c, w, p = instance(seed, integer=True, zero_weights=seed % 2 == 1)
        assert greedy(c, w, p).tolist() == brute_force_greedy(c, w, p), seed


@pytest.mark.parametrize(("integer", "zero_weights"), KINDS)
def test_fast_interchange_takes_the_swaps_of_the_numpy_form(
    integer: bool, zero_weights: bool
) -> None:
    for seed in range(150):
        c, w, p = instance(seed, integer=integer, zero_weights=zero_weights)
        rng = np.random.default_rng([seed, 1])
        for start in (
            rng.choice(c.shape[0], size=p, replace=False),
            reference_greedy(c, w, p),
        ):
            expected = reference_fast_interchange(c, w, start)
            assert fast_interchange(c, w, start).tolist() == expected.tolist(), seed


def test_fast_interchange_on_larger_instances() -> None:
    """Hundreds of sites and atoms, weights with repeats (a reservoir's counts)."""
    for seed in range(12):
        rng = np.random.default_rng([seed, 2])
        n, m, p = 300, 500, int(rng.integers(5, 30))
        c = rng.uniform(0.0, 100.0, size=(n, m)) ** 1.5
        w = rng.integers(0, 4, size=m).astype(np.float64)
        start = rng.choice(n, size=p, replace=False)
        assert fast_interchange(c, w, start).tolist() == (
            reference_fast_interchange(c, w, start).tolist()
        )
        assert greedy(c, w, p).tolist() == reference_greedy(c, w, p).tolist()


def test_fast_interchange_ends_where_no_single_swap_helps() -> None:
    """The result is a local optimum of the swap neighbourhood, checked swap by swap."""
    for seed in range(20):
        c, w, p = instance(seed, integer=False, zero_weights=False)
        sites = fast_interchange(c, w, np.arange(p))
        value = _value(c, w, sites)
        closed = np.setdiff1d(np.arange(c.shape[0]), sites)
        for r, i in itertools.product(range(p), closed.tolist()):
            swapped = sites.copy()
            swapped[r] = i
            assert _value(c, w, swapped) >= value * (1 - 1e-9)


def test_every_site_open_and_a_single_site() -> None:
    c = np.array([[1.0, 3.0], [2.0, 0.5], [4.0, 4.0]])
    w = np.array([1.0, 2.0])
    assert fast_interchange(c, w, np.array([2, 0, 1])).tolist() == [2, 0, 1]
    assert greedy(c, w, 3).tolist() == [0, 1, 2]
    assert fast_interchange(c, w, np.array([2])).tolist() == [1]
    assert greedy(c, w, 1).tolist() == [1]


def test_impossible_site_counts_are_refused() -> None:
    c = np.ones((3, 2))
    w = np.ones(2)
    with pytest.raises(ValueError, match="greedy addition"):
        greedy(c, w, 4)
    with pytest.raises(ValueError, match="open site"):
        fast_interchange(c, w, np.array([], dtype=np.int64))
    assert greedy(c, w, 0).tolist() == []


def reference_nearest(
    c: FloatArray, w: FloatArray, sites: IntArray
) -> tuple[FloatArray, FloatArray, sp.csr_array]:
    """Every atom's cheapest and second cheapest open cost, and the sparse ``(p, m)``
    matrix of the weights by the position of the cheapest (a stable sort's first)."""
    m = c.shape[1]
    sub = c[sites]
    order = np.argsort(sub, axis=0, kind="stable")
    atoms = np.arange(m)
    c1 = sub[order[0], atoms]
    c2 = sub[order[1], atoms] if sites.size > 1 else np.full(m, np.inf)
    return c1, c2, sp.csr_array((w, (order[0], atoms)), shape=(sites.size, m))


def reference_losses(c: FloatArray, w: FloatArray, sites: IntArray) -> FloatArray:
    """``loss_ir`` of every site by scipy's sparse product, as the reference pass forms it."""
    c1, c2, owner = reference_nearest(c, w, sites)
    fallback = np.maximum(np.minimum(c, c2) - c1, 0.0)
    return np.asarray((owner @ fallback.T).T)


@pytest.mark.parametrize(("integer", "zero_weights"), KINDS)
def test_kept_losses_equal_a_full_sum_after_every_swap(integer: bool, zero_weights: bool) -> None:
    """The losses kept across swaps are those a full pass sums, bit for bit, and the
    gains summed four sites at a time are those summed one at a time."""
    for seed in range(80):
        c, w, p = instance(seed, integer=integer, zero_weights=zero_weights)
        n, m = c.shape
        if p == n:
            continue
        rng = np.random.default_rng([seed, 3])
        sites = rng.choice(n, size=p, replace=False)
        is_open = np.zeros(n, dtype=bool)
        is_open[sites] = True
        c1, c2, a1 = np.empty(m), np.empty(m), np.empty(m, dtype=np.int64)
        nearest_two(c, sites, c1, c2, a1)
        gains = np.full(n, np.nan)
        fill_gains(c, w, c1, np.flatnonzero(~is_open), gains)
        for i in np.flatnonzero(~is_open):
            assert gains[i] == gain_of(c, w, c1, int(i)), seed
        losses = np.full((n, p), np.nan)
        kept: BoolArray = np.asarray(rng.random(n) < 0.7)
        kept[sites] = False
        fill_losses(c, w, c1, c2, a1, np.flatnonzero(kept), losses)
        ct = np.ascontiguousarray(c.T)
        for _ in range(4):
            leave = int(rng.integers(p))
            enter = int(rng.choice(np.flatnonzero(~is_open)))
            closing = int(sites[leave])
            sites = sites.copy()
            sites[leave] = enter
            is_open[closing], is_open[enter] = False, True
            kept[closing] = kept[enter] = False
            n1, n2, b1 = np.empty(m), np.empty(m), np.empty(m, dtype=np.int64)
            nearest_two(c, sites, n1, n2, b1)
            swap_losses(ct, w, c1, c2, a1, n1, n2, b1, losses, kept)
            expected = reference_losses(c, w, sites)
            assert np.array_equal(losses[kept], expected[kept]), seed
            c1, c2, a1 = n1, n2, b1


def test_a_shared_transposed_matrix_gives_the_same_swaps() -> None:
    for seed in range(30):
        c, w, p = instance(seed, integer=False, zero_weights=False)
        start = np.random.default_rng([seed, 4]).choice(c.shape[0], size=p, replace=False)
        shared = fast_interchange(c, w, start, transposed=np.ascontiguousarray(c.T))
        assert shared.tolist() == fast_interchange(c, w, start).tolist(), seed
