"""Consolidation: the p-median of recent targets, kept only where it serves unseen ones better.

A first-order rule keeps the local minima of online k-means: vehicles that
never win a target, the wrong number of vehicles per hotspot, and on a
directed network references stranded past a junction. From time to time the
``consolidating`` fleet therefore solves the batch problem on a bounded
reservoir of its most recent targets ``z_1 .. z_m``:

.. math:: \\min_{S, |S| = p} \\sum_j c\\bigl(\\min_{s \\in S} d(s, z_j)\\bigr),

objective (11) of Le Ny & Pappas on the empirical distribution, over the
candidate references of the sample (its targets and the ends of their edges,
Hakimi's finite dominating set; at most :data:`MAX_SITE_TARGETS` of its targets)
by greedy addition and Whitaker's fast
interchange (:mod:`routing_svc.sa.interchange`), started from the current
references, from the last accepted ones and from scratch; the solve that is taken
goes on by variable neighbourhood search.

A p-median of ``m`` targets fits their noise: taken blindly it would pull a
fleet that already stands at the optimum away from it. So the reservoir is
split into ``folds`` folds (place ``i`` in fold ``i % folds``) and solved without
each fold in turn; every *fresh* target (one that came after the current
references were accepted, so that they were not fitted to it) is then priced from
the configuration solved without its fold, a cross-validated estimate of what
solving again gains over the current references. Only if the
gain exceeds ``confidence`` standard errors of the paired differences
(``settled_confidence`` once the epoch's clock has reached ``longest`` or the
references are the fit of a full reservoir of the epoch; at least
``unfitted_confidence`` while no consolidation of the epoch has fitted the references,
which held steps then do not move either) is the
problem solved on the whole reservoir, from the current and the last accepted
references and from scratch, and the best replaces the references; each
vehicle's step counter restarts at the number of reservoir targets it now
serves, so that the paper's steps (eq. (10)) go on at the size of a fleet that
has seen them.

Consolidations follow the demand's clock: ``first`` targets into an *epoch*, then
each time the targets seen in the epoch have grown by the factor ``growth``, the
period capped at ``longest``; and each time the targets since the references were
last replaced have grown by that factor, that period capped at ``slowest``, so that a
fleet whose consolidations keep being turned down (it has learnt a demand that
stays) consolidates ever more rarely. A consolidation taken with a cross-validated
gain beyond ``hasten`` standard errors restarts the epoch's clock: references that far
off mean that the demand moves (or is still being learnt), so the next comes ``first``
targets later. The mean cost of
each block of targets is compared with the mean cost expected of the references
at the last consolidation. Blocks in a row that each cost ``shift_ratio`` times more,
together by more than ``shift_confidence`` standard errors of their mean (so that the
heavy tail of a concentrated demand's costs is not taken for a move, while a moderate
move shows within a few blocks), start a new epoch (the demand moved): the reservoir
keeps the last block only and the schedule starts again. A demand can also move where its
cost does not grow (hotspots that move closer together): so, in a fleet that learns as one,
each block of targets is also tested for who won them. Under the demand the references
were last fitted to, the closest reference of each target falls on vehicle ``i`` with the
share ``pi_i`` it served of their reservoir; a block's wins whose G statistic against
these shares exceeds the chi-square quantile of ``1 - share_alpha`` (``p - 1`` degrees
of freedom) start a new epoch as well.

Each consolidation is recorded with the target that triggered it
(:class:`Consolidation`), so that replay applies it without solving again.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Generic, Protocol, runtime_checkable

import numpy as np
from scipy.special import chdtri

from routing_svc.errors import InvalidInput
from routing_svc.sa.interchange import fast_interchange, greedy, neighbourhood_search
from routing_svc.sa.space import P
from routing_svc.sa.stands import StandSet, capacitated_sites, open_count, stand_assignment
from routing_svc.types import FloatArray, IntArray

MAX_SITE_TARGETS = 1500
"""Reservoir targets offered as candidate references (with the ends of their edges);
beyond, an evenly spaced subset of the distinct targets, so that a consolidation's cost
is bounded whatever the spread of the demand."""


ShiftRun = tuple[float, float, int]
"""Targets of the shift test: the sum of their costs, of their squared costs, and their count."""

NO_SHIFT_RUN: ShiftRun = (0.0, 0.0, 0)


@dataclass(frozen=True, slots=True)
class ConsolidationPolicy:
    """When and how a ``consolidating`` fleet consolidates (see the module docstring).

    Attributes
    ----------
    reservoir : int
        The most recent targets kept (any one vehicle required).
    first : int
        Targets into an epoch of the first consolidation.
    growth : float
        Each period is ``growth - 1`` times the targets seen in the epoch (at least
        ``first``).
    longest : int
        The longest period of the epoch's clock.
    slowest : int
        The longest period of the clock since the references were last replaced
        (at least ``longest``); a period is the longer of the two clocks'.
    hasten : float or None
        A consolidation taken with a cross-validated gain beyond this many standard
        errors restarts the epoch's clock (:meth:`next_after`), so that a demand that
        keeps moving is fitted every ``first`` targets or so, not every tenth of the
        epoch; ``None``: the clock runs from the epoch's start.
    folds : int
        Folds of the cross-validated test.
    confidence : float
        Standard errors by which the cross-validated gain must exceed zero.
    settled_confidence : float
        The same, once the epoch's clock has reached ``longest`` (a demand that has
        stayed for ``longest / (growth - 1)`` targets), where a fit of the reservoir
        is as good an estimate as it will get and a gain within the noise is no reason
        to move.
    full_fit_settles : bool
        References a consolidation of this epoch fitted to a full reservoir face
        ``settled_confidence`` before the epoch's clock reaches ``longest``: a fit of a
        reservoir no larger is no better an estimate of the same demand, and one taken
        on a gain within the noise moves a fleet at random among its sample's fits.
    unfitted_confidence : float
        The least confidence while the references are not a consolidation's fit of this
        epoch's targets: those the fleet was created with (perhaps a good configuration,
        perhaps not), or those of the demand before a shift. A fit of a few hundred
        targets then faces references it knows nothing about, and a cross-validated gain
        within the noise, taken, would replace a good configuration by a sample's noise.
        Meanwhile held steps do not move the references either (0: neither).
    block : int
        Targets per block of the shift test.
    shift_ratio : float
        Blocks whose mean cost exceeds this times the baseline of the last
        consolidation can start a new epoch (see :meth:`starts_epoch`).
    shift_confidence : float
        Standard errors of the mean of such blocks in a row (from their own spread) by
        which it must exceed ``shift_ratio`` times the baseline; 0: the ratio alone
        decides, at the first such block.
    share_alpha : float or None
        The false-alarm probability of the test of each block's winners against the
        shares the references served of the reservoir they were last fitted to
        (:meth:`shares_moved`); ``None``: no such test.
    refit : float or None
        References that a consolidation fitted to ``m`` targets of the epoch give way to
        the fit of a reservoir of at least ``refit * m`` targets unless the
        cross-validated test finds it worse by more than one standard error (more
        targets of the same demand make a better estimate of its p-median); ``None``:
        only the test decides.
    tested_refit : bool
        Whether such a refit faces the test at all. The test's challengers are fitted
        to ``(folds - 1) / folds`` of the reservoir, no more targets than the
        references had until it has outgrown their fit by ``folds / (folds - 1)``, so
        while it grows by less it turns the better estimate down on noise; untested,
        the fit of the whole reservoir is taken (and no fold is solved).
    fresh_baseline : bool
        The shift test's baseline is :attr:`Consolidation.fresh_baseline` (the cost of
        targets the references were not fitted to), else :attr:`Consolidation.baseline`.
    checked_moves : bool
        A held step that would move a reference is taken only if it lowers the
        reservoir's mean cost (:func:`move_pays`), so that a jump of ``J`` that the
        step's direction does not see is never paid blindly.
    shakes : int
        The accepted solve goes on from its best local optimum by variable
        neighbourhood search until this many shakes in a row found nothing better
        (:func:`routing_svc.sa.interchange.neighbourhood_search`); 0: the local
        optimum is kept.
    shared_targets : bool
        In a fleet that learns per type, a target that needed any one vehicle feeds
        every type, each pricing it by the first arrival of the others
        (:meth:`ConsolidationJob.ceilings`); else it feeds none.
    """

    reservoir: int = 4000
    first: int = 250
    growth: float = 1.1
    longest: int = 4000
    slowest: int = 32000
    hasten: float | None = 3.0
    folds: int = 4
    confidence: float = 0.0
    settled_confidence: float = 1.0
    full_fit_settles: bool = True
    unfitted_confidence: float = 3.0
    block: int = 250
    shift_ratio: float = 1.25
    shift_confidence: float = 2.0
    share_alpha: float | None = 1e-9
    refit: float | None = 1.1
    tested_refit: bool = False
    fresh_baseline: bool = True
    checked_moves: bool = True
    shakes: int = 20
    shared_targets: bool = True

    def __post_init__(self) -> None:
        for name in ("reservoir", "first", "longest", "block", "folds"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 2:
                raise InvalidInput(f"consolidation {name} must be an integer >= 2, got {value!r}")
        if isinstance(self.slowest, bool) or not isinstance(self.slowest, int):
            raise InvalidInput(f"consolidation slowest must be an integer, got {self.slowest!r}")
        if self.slowest < self.longest:
            raise InvalidInput("consolidation slowest must be at least longest")
        if self.block > self.reservoir:
            raise InvalidInput("the consolidation block must fit in the reservoir")
        if not (math.isfinite(self.growth) and self.growth > 1.0):
            raise InvalidInput("consolidation growth must be a finite number > 1")
        for name in ("confidence", "settled_confidence", "unfitted_confidence", "shift_confidence"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, float | int):
                raise InvalidInput(f"consolidation {name} must be a number, got {value!r}")
            if not (math.isfinite(value) and value >= 0.0):
                raise InvalidInput(f"consolidation {name} must be a finite number >= 0")
        if self.hasten is not None and not (
            isinstance(self.hasten, float | int)
            and not isinstance(self.hasten, bool)
            and math.isfinite(self.hasten)
            and self.hasten >= 0.0
        ):
            raise InvalidInput("consolidation hasten must be a finite number >= 0, or null")
        if self.share_alpha is not None and not (
            isinstance(self.share_alpha, float | int)
            and not isinstance(self.share_alpha, bool)
            and 0.0 < self.share_alpha < 1.0
        ):
            raise InvalidInput("consolidation share_alpha must be a number in (0, 1), or null")
        if not (math.isfinite(self.shift_ratio) and self.shift_ratio > 1.0):
            raise InvalidInput("consolidation shift_ratio must be a finite number > 1")
        if self.refit is not None and not (
            isinstance(self.refit, float | int)
            and not isinstance(self.refit, bool)
            and math.isfinite(self.refit)
            and self.refit > 1.0
        ):
            raise InvalidInput("consolidation refit must be a finite number > 1, or null")
        if isinstance(self.shakes, bool) or not isinstance(self.shakes, int) or self.shakes < 0:
            raise InvalidInput(f"consolidation shakes must be an integer >= 0, got {self.shakes!r}")
        for flag in (
            "tested_refit",
            "fresh_baseline",
            "checked_moves",
            "shared_targets",
            "full_fit_settles",
        ):
            if not isinstance(getattr(self, flag), bool):
                raise InvalidInput(f"consolidation {flag} must be true or false")

    def to_dict(self) -> dict[str, Any]:
        return {
            "reservoir": self.reservoir,
            "first": self.first,
            "growth": self.growth,
            "longest": self.longest,
            "folds": self.folds,
            "confidence": self.confidence,
            "block": self.block,
            "shift_ratio": self.shift_ratio,
            # a policy stored before any of these keeps the bytes it had then
            **({"slowest": self.slowest} if self.slowest != self.longest else {}),
            **({} if self.hasten is None else {"hasten": self.hasten}),
            **({} if self.share_alpha is None else {"share_alpha": self.share_alpha}),
            **(
                {"settled_confidence": self.settled_confidence}
                if self.settled_confidence != self.confidence
                else {}
            ),
            **({} if self.refit is None else {"refit": self.refit}),
            **({} if self.tested_refit else {"tested_refit": False}),
            **({"fresh_baseline": True} if self.fresh_baseline else {}),
            **({"checked_moves": True} if self.checked_moves else {}),
            **({"shared_targets": True} if self.shared_targets else {}),
            **({"full_fit_settles": True} if self.full_fit_settles else {}),
            **({"shakes": self.shakes} if self.shakes else {}),
            **({"shift_confidence": self.shift_confidence} if self.shift_confidence else {}),
            **(
                {"unfitted_confidence": self.unfitted_confidence}
                if self.unfitted_confidence
                else {}
            ),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ConsolidationPolicy:
        """A stored policy; one stored without ``refit``, ``tested_refit``,
        ``fresh_baseline``, ``checked_moves``, ``shakes``, ``slowest``,
        ``settled_confidence``, ``shift_confidence``, ``unfitted_confidence``,
        ``hasten``, ``shared_targets``, ``full_fit_settles`` or ``share_alpha`` keeps the
        behaviour it was stored with (no refit, a refit tested, the reservoir's baseline,
        unchecked moves, no shakes, the epoch's clock alone, one confidence throughout,
        the shift test's ratio alone, no more asked of references no consolidation
        fitted, a clock that runs from the epoch's start, targets for any one vehicle
        feeding no type, settled by the clock alone, no test of the winners)."""
        if not isinstance(data, dict):
            raise InvalidInput("consolidation must be an object")
        legacy = {
            "refit": None,
            "tested_refit": True,
            "fresh_baseline": False,
            "checked_moves": False,
            "shakes": 0,
            "shift_confidence": 0.0,
            "unfitted_confidence": 0.0,
            "hasten": None,
            "shared_targets": False,
            "full_fit_settles": False,
            "share_alpha": None,
        }
        unknown = set(data) - {*cls().to_dict(), *legacy, "slowest", "settled_confidence"}
        if unknown:
            raise InvalidInput(f"unknown consolidation fields: {sorted(unknown)}")
        default = cls()
        same = {
            "slowest": data.get("longest", default.longest),
            "settled_confidence": data.get("confidence", default.confidence),
        }
        return cls(**{**legacy, **same, **data})

    def _growth_of(self, targets: int) -> int:
        """``growth - 1`` times ``targets``, rounded up: a clock's uncapped period (a
        product within rounding error of an integer is that integer: ``1.1 - 1`` is not
        exactly a tenth)."""
        return math.ceil(round(targets * (self.growth - 1.0), 9))

    def next_after(self, *, now: int, epoch: int, accepted_at: int, hastened_at: int = 0) -> int:
        """The target count of the next consolidation after one at ``now``, in an epoch
        that began at ``epoch``, references last replaced at ``accepted_at``, the
        epoch's clock last restarted (:attr:`hasten`) at ``hastened_at``."""
        clock = min(max(self._growth_of(now - max(epoch, hastened_at)), self.first), self.longest)
        quiet = min(self._growth_of(now - max(epoch, accepted_at)), self.slowest)
        return now + max(clock, quiet)

    def confidence_at(self, *, due: int, epoch: int, fitted: int) -> float:
        """The confidence of the consolidation due at ``due`` in an epoch that began at
        ``epoch``, the references a consolidation's fit of ``fitted`` of this epoch's
        targets (0: none): :attr:`settled_confidence` once the epoch's clock has reached
        :attr:`longest` (or, with :attr:`full_fit_settles`, once ``fitted`` fills the
        reservoir), else :attr:`confidence`; at least :attr:`unfitted_confidence`
        while ``fitted`` is 0."""
        full = self.full_fit_settles and fitted >= self.reservoir
        settled = full or self._growth_of(due - epoch) >= self.longest
        asked = self.settled_confidence if settled else self.confidence
        return asked if fitted else max(asked, self.unfitted_confidence)

    def shift_run(self, run: ShiftRun, block: ShiftRun, baseline: float | None) -> ShiftRun:
        """The blocks in a row that exceed the ratio, after ``block``: ``run`` and
        ``block`` added up where the block's mean cost exceeds :attr:`shift_ratio` times
        ``baseline``, else none (each a cost sum, a squared-cost sum and a size)."""
        total, squares, size = block
        if baseline is None or size == 0 or total / size <= self.shift_ratio * baseline:
            return NO_SHIFT_RUN
        return run[0] + total, run[1] + squares, run[2] + size

    def starts_epoch(
        self, *, cost_sum: float, square_sum: float, size: int, baseline: float | None
    ) -> bool:
        """Whether ``size`` targets whose costs sum to ``cost_sum`` (their squares to
        ``square_sum``), the blocks in a row that each exceeded the ratio, show that the
        demand moved: their mean exceeds :attr:`shift_ratio` times ``baseline`` by more
        than :attr:`shift_confidence` standard errors of that mean. No baseline (no
        consolidation yet in the epoch): no.
        """
        if baseline is None or size < 2:
            return False
        mean = cost_sum / size
        spread = max(square_sum - size * mean * mean, 0.0) / (size - 1)
        excess = mean - self.shift_ratio * baseline
        return excess > 0.0 and excess > self.shift_confidence * math.sqrt(spread / size)

    def shares_moved(
        self, wins: Sequence[int], served: Sequence[int], places: Sequence[object] = ()
    ) -> bool:
        """Whether a block's ``wins`` per vehicle (whose reference was closest to each
        target) show that the demand moved: their G statistic
        ``2 sum_i w_i ln(w_i / (n pi_i))`` against the shares ``pi`` of the ``served``
        counts of the last fit (:func:`expected_shares`) exceeds the chi-square quantile
        of ``1 - share_alpha`` with ``p - 1`` degrees of freedom (``p`` the vehicles, or
        their distinct ``places``: vehicles that share a reference, at a stand, share
        their wins and counts, however the ties between them fall); never without
        :attr:`share_alpha` or with fewer than two places."""
        if places:
            cell: dict[object, int] = {}
            merged_wins: list[int] = []
            merged_served: list[int] = []
            for place, won, count in zip(places, wins, served, strict=True):
                at = cell.setdefault(place, len(merged_wins))
                if at == len(merged_wins):
                    merged_wins.append(0)
                    merged_served.append(0)
                merged_wins[at] += won
                merged_served[at] += count
            wins, served = merged_wins, merged_served
        if self.share_alpha is None or len(wins) < 2 or len(wins) != len(served):
            return False
        size = sum(wins)
        shares = expected_shares(served)
        statistic = 2.0 * sum(
            won * math.log(won / (size * share))
            for won, share in zip(wins, shares, strict=True)
            if won > 0
        )
        return statistic > _chi_square_quantile(self.share_alpha, len(wins) - 1)

    def hastens(self, done: Consolidation[Any]) -> bool:
        """Whether ``done`` restarts the epoch's clock: taken, with a cross-validated
        gain beyond :attr:`hasten` standard errors (an untested refit has none)."""
        return (
            self.hasten is not None
            and done.accepted
            and done.standard_error > 0.0
            and -done.gain > self.hasten * done.standard_error
        )

    def apply_by(self, *, due: int, epoch: int, accepted_at: int, hastened_at: int = 0) -> int:
        """The target count by which a consolidation that fell due at ``due`` and is
        solved away from the fleet must be applied: when the one after it would fall due
        were it applied at ``due``, so that however fast targets come the schedule keeps
        its shape and a solve has the whole period to end in. The epoch's
        first (``due - epoch <= first``: the references are the fleet's start or those
        of the demand before a shift) is applied at once, by the target after ``due``:
        its reservoir is small, and a batch of a few hundred targets must not leave a
        new fleet where it started."""
        if due - epoch <= self.first:
            return due
        return self.next_after(
            now=due, epoch=epoch, accepted_at=accepted_at, hastened_at=hastened_at
        )


def expected_shares(served: Sequence[int]) -> list[float]:
    """Each vehicle's expected share of the targets, from the reservoir targets it served
    at the last fit, with half a target added to each (no share is 0)."""
    total = sum(served) + 0.5 * len(served)
    return [(count + 0.5) / total for count in served]


@lru_cache(maxsize=64)
def _chi_square_quantile(alpha: float, degrees: int) -> float:
    """The value a chi-square variable of ``degrees`` degrees of freedom exceeds with
    probability ``alpha``."""
    return float(chdtri(degrees, alpha))


@dataclass(frozen=True, slots=True)
class Consolidation(Generic[P]):
    """What one consolidation decided (recorded, so replay need not solve again).

    Attributes
    ----------
    accepted : bool
        Whether the references changed.
    positions : tuple
        Every vehicle's reference afterwards (in the fleet's id order).
    updates : tuple of int
        Every vehicle's step counter afterwards.
    sample : int
        Targets in the reservoir.
    sample_before, sample_after : float
        Mean cost ``c(T)`` of the reservoir's targets from the references before and
        after.
    gain, standard_error : float
        The cross-validated change of the mean cost that solving again brings
        (negative: better), and its standard error.
    fresh_before : float or None
        Mean cost from the references before of the targets that tested them (those
        they were not fitted to); ``None`` when none did, or in a record that predates it.
    """

    accepted: bool
    positions: tuple[P, ...]
    updates: tuple[int, ...]
    sample: int
    sample_before: float
    sample_after: float
    gain: float
    standard_error: float
    fresh_before: float | None = None

    def to_dict(self, encode: Callable[[P], dict[str, object]]) -> dict[str, Any]:
        data: dict[str, Any] = {
            "accepted": self.accepted,
            "positions": [encode(p) for p in self.positions],
            "updates": list(self.updates),
            "sample": self.sample,
            "sample_before": self.sample_before,
            "sample_after": self.sample_after,
            "gain": self.gain,
            "standard_error": self.standard_error,
        }
        if self.fresh_before is not None:
            data["fresh_before"] = self.fresh_before
        return data

    @property
    def fresh_baseline(self) -> float:
        """The mean cost to expect from the references afterwards, measured only on
        targets they were not fitted to: the tested targets' cost before plus the
        cross-validated gain when accepted (a refit taken untested has none);
        :attr:`baseline` when nothing was tested."""
        if self.fresh_before is None:
            return self.baseline
        return self.fresh_before + self.gain if self.accepted else self.fresh_before

    @property
    def baseline(self) -> float:
        """The mean cost to expect from the references afterwards, the baseline of the
        shift test: the cross-validated estimate when accepted (the fit on the whole
        reservoir is no fair measure of its own targets), else the cost before."""
        return self.sample_before + min(self.gain, 0.0) if self.accepted else self.sample_before

    @classmethod
    def from_dict(
        cls, data: dict[str, Any], decode: Callable[[dict[str, object]], P]
    ) -> Consolidation[P]:
        try:
            return cls(
                accepted=bool(data["accepted"]),
                positions=tuple(decode(p) for p in data["positions"]),
                updates=tuple(int(u) for u in data["updates"]),
                sample=int(data["sample"]),
                sample_before=float(data["sample_before"]),
                sample_after=float(data["sample_after"]),
                gain=float(data["gain"]),
                standard_error=float(data["standard_error"]),
                fresh_before=None
                if data.get("fresh_before") is None
                else float(data["fresh_before"]),
            )
        except (KeyError, TypeError, ValueError):
            raise InvalidInput("a recorded consolidation is malformed") from None


@runtime_checkable
class SampleSpace(Protocol[P]):
    """What a consolidation needs of a space: candidates and a cost matrix."""

    def candidate_references(self, sample: Sequence[P], fixed: Sequence[P]) -> list[P]:
        """``fixed`` first, then candidate references for ``sample``, without repeats."""
        ...

    def cost_matrix(self, sources: list[P], targets: list[P]) -> FloatArray:
        """Directed costs, shape ``(len(sources), len(targets))``."""
        ...


def consolidate(
    space: SampleSpace[P],
    positions: Sequence[P],
    anchor: Sequence[P],
    reservoir: Sequence[P],
    *,
    power: float,
    speed: float,
    confidence: float,
    updates: Sequence[int],
    fresh: int,
    folds: int = 2,
    refit: bool = False,
    tested_refit: bool = True,
    stands: StandSet[P] | None = None,
    shakes: int = 0,
    floors: Sequence[float] | None = None,
    ceilings: Sequence[float] | None = None,
) -> Consolidation[P]:
    """Solve the reservoir without each fold, test on that fold, solve all if it pays.

    Parameters
    ----------
    space : SampleSpace
        The space.
    positions : sequence
        The current references, in the fleet's id order.
    anchor : sequence
        The last accepted references (a start of every solve).
    reservoir : sequence
        The recent targets, oldest first; place ``i`` is in fold ``i % folds``.
    power : float
        ``q`` of the service cost ``c(T) = T**q``.
    speed : float
        The speed factor of every vehicle (they are identical): ``T = D / speed``.
    confidence : float
        Standard errors of the cross-validated test.
    updates : sequence of int
        The step counters, returned unchanged when nothing is accepted.
    fresh : int
        How many of the reservoir's last targets came after the current references
        were accepted: only they test.
    folds : int
        Folds of the cross-validation (at least 2).
    refit : bool
        The references were fitted to a reservoir this one outgrows
        (:attr:`ConsolidationPolicy.refit`): solving all is taken unless the test finds
        it worse by more than one standard error.
    tested_refit : bool
        ``False``: a refit is taken without the test (no fold is solved; the gain and
        its standard error are recorded as 0), if a fresh target prices the
        references before.
    stands : StandSet, optional
        Solve over these stands only, with their capacities
        (:func:`routing_svc.sa.stands.capacitated_sites`); the cost before is that of
        the vehicles' stands (:func:`routing_svc.sa.stands.stand_assignment`), and the
        references accepted are stands.
    shakes : int
        Shakes without gain of the accepted solve's neighbourhood search
        (:attr:`ConsolidationPolicy.shakes`).
    floors : sequence of float, optional
        Per reservoir target, a cost ``f`` below which it is not served
        (:meth:`ConsolidationJob.floors`: the last arrival of the other types it
        needed). A target then costs ``max(c, f)`` from references ``c`` away: the
        term of objective (11) with the other types fixed. Every fit is the p-median
        of the plain costs improved by the fast interchange on these
        (:func:`priced_fit`); the test and the costs recorded use these. Not with
        ``stands``.
    ceilings : sequence of float, optional
        Per reservoir target, a cost ``u`` above which it is served anyway
        (:meth:`ConsolidationJob.ceilings`: the first arrival of the other types, for a
        target that needed any one vehicle; ``inf`` for none). A target then costs
        ``max(min(c, u), f)``: with ``floors``, objective (11) with the other types
        fixed. Fitted, tested and recorded as with ``floors``. Not with ``stands``.
    """
    p = len(positions)
    if len(reservoir) < 2 or len(anchor) != p or len(updates) != p:
        raise InvalidInput("a consolidation needs two targets and one anchor per vehicle")
    if isinstance(folds, bool) or not isinstance(folds, int) or folds < 2:
        raise InvalidInput(f"a consolidation needs at least 2 folds, got {folds!r}")
    if floors is not None and (len(floors) != len(reservoir) or stands is not None):
        raise InvalidInput("floors need one value per reservoir target, and no stands")
    if floors is not None and not all(math.isfinite(f) and f >= 0.0 for f in floors):
        raise InvalidInput("floors must be finite and >= 0")
    if ceilings is not None and (len(ceilings) != len(reservoir) or stands is not None):
        raise InvalidInput("ceilings need one value per reservoir target, and no stands")
    if ceilings is not None and not all(u >= 0.0 for u in ceilings):  # NaN fails too
        raise InvalidInput("ceilings must be >= 0 (inf: none)")
    low = list(floors) if floors is not None and any(f > 0.0 for f in floors) else None
    high = list(ceilings) if ceilings is not None and any(map(math.isfinite, ceilings)) else None
    priced = low is not None or high is not None
    entries: list[Any] = [*reservoir]
    if priced:  # a column per target and price: (target, floor, ceiling)
        m = len(reservoir)
        entries = list(zip(reservoir, low or [0.0] * m, high or [math.inf] * m, strict=True))
    keys = list(dict.fromkeys(entries))
    targets = [z for z, _, _ in keys] if priced else keys
    column = {z: j for j, z in enumerate(keys)}
    places = np.fromiter((column[z] for z in entries), dtype=np.int64, count=len(reservoir))
    parts = [
        np.bincount(places[f::folds], minlength=len(targets)).astype(np.float64)
        for f in range(folds)
    ]
    weight = np.sum(parts, axis=0)
    first_fresh = len(reservoir) - min(max(fresh, 0), len(reservoir))
    if stands is None:
        distinct = list(dict.fromkeys(targets)) if priced else targets
        stride = -(-len(distinct) // MAX_SITE_TARGETS)
        sites = space.candidate_references(distinct[::stride], [*positions, *anchor])
        row = {s: i for i, s in enumerate(sites)}
        actual = np.array([row[x] for x in positions], dtype=np.int64)
        current = _distinct(actual, len(sites))
        anchored = _distinct(np.array([row[x] for x in anchor], dtype=np.int64), len(sites))
    else:  # the vehicles serve from their stands, and only stands open
        sites = list(stands.positions)
        opened = open_count(p, len(sites))
        actual = _stand_rows(space, stands, positions)
        current = _padded(actual, opened, len(sites))
        anchored = _padded(_stand_rows(space, stands, anchor), opened, len(sites))
    costs = np.asarray(space.cost_matrix(sites, targets), dtype=np.float64)  # a new matrix
    costs /= speed
    costs **= power
    plain = costs
    if priced:
        ceiling = np.array([u for _, _, u in keys])
        costs = np.maximum(np.minimum(plain, ceiling), np.array([f for _, f, _ in keys]))
    now = costs[actual].min(axis=0)
    before = float(weight @ now) / float(weight.sum())

    def taken(gain: float, standard_error: float, fresh_before: float) -> Consolidation[P]:
        """Solve the whole reservoir and take its best."""

        def solved(_: int) -> IntArray:
            return priced_fit(plain, costs, weight, [current, anchored], shakes)

        if stands is None:
            ordered = _pair(current, solved(p))
        else:
            ordered = _pair(actual, capacitated_sites(costs, weight, stands.capacities, p, solved))
        chosen_costs = costs[ordered]
        owner = chosen_costs.argmin(axis=0)
        served = np.bincount(owner, weights=weight, minlength=p)
        after = float(weight @ chosen_costs[owner, np.arange(owner.size)]) / float(weight.sum())
        return Consolidation(
            True,
            tuple(sites[i] for i in ordered.tolist()),
            tuple(round(s) for s in served.tolist()),
            len(reservoir),
            before,
            after,
            gain,
            standard_error,
            fresh_before,
        )

    if refit and not tested_refit:
        fresh_weight = np.bincount(places[first_fresh:], minlength=len(targets))
        if fresh_weight.any():
            return taken(0.0, 0.0, float(fresh_weight @ now) / float(fresh_weight.sum()))
    tests = [
        np.bincount(
            places[first_fresh + (f - first_fresh) % folds :: folds], minlength=len(targets)
        ).astype(np.float64)
        for f in range(folds)
    ]
    folds_tested = [(part, test, test > 0) for part, test in zip(parts, tests, strict=True)]
    folds_tested = [fold for fold in folds_tested if fold[2].any()]
    challengers = _fold_fits(
        plain, costs, weight, [part for part, _, _ in folds_tested], [current, anchored]
    )
    differences, weights, tested_now = [], [], []
    for (_, test, tested), challenger in zip(folds_tested, challengers, strict=True):
        differences.append((costs[challenger].min(axis=0) - now)[tested])
        weights.append(test[tested])
        tested_now.append(now[tested])
    if not differences:
        return Consolidation(
            False, tuple(positions), tuple(updates), len(reservoir), before, before, 0.0, 0.0
        )
    difference, tested_weight = np.concatenate(differences), np.concatenate(weights)
    total = float(tested_weight.sum())
    gain = float(tested_weight @ difference) / total
    spread = float(tested_weight @ (difference - gain) ** 2) / total
    standard_error = math.sqrt(max(spread, 0.0) / total)
    fresh_before = float(tested_weight @ np.concatenate(tested_now)) / total
    pays = gain < -confidence * standard_error and gain < 0.0
    if not (pays or (refit and gain <= standard_error)):
        return Consolidation(
            False, tuple(positions), tuple(updates), len(reservoir), before, before, gain,
            standard_error, fresh_before,
        )  # fmt: skip
    return taken(gain, standard_error, fresh_before)


ANY_VEHICLE: tuple[str, ...] = ("",)
"""The partners kept for a target that needed any one vehicle (no type is named ``""``):
the first arrival of every type serves it (:meth:`ConsolidationJob.ceilings`)."""


def partners_of(kind: str, requires: Sequence[str] | None) -> tuple[str, ...]:
    """What a type's reservoir keeps of a target's needs (:attr:`Learning.partners`): the
    other types it needed, in name order, or :data:`ANY_VEHICLE` for any one vehicle."""
    if not requires:
        return ANY_VEHICLE
    return tuple(sorted({k for k in requires if k != kind}))


ConsolidationKey = tuple[int, int, int]
"""Which due consolidation a job is for: the first vehicle of the group it moves (0 for
the whole fleet), the group's epoch and the count it was due at (both only grow, so a
key names one consolidation of a fleet's life)."""


@dataclass(frozen=True, slots=True)
class ConsolidationJob(Generic[P]):
    """A due consolidation's inputs, copied when it fell due, so that it can be solved
    away from the fleet (another thread or process) and applied later
    (:meth:`routing_svc.sa.fleet.Fleet.consolidation_job`). The arguments are those of
    :func:`consolidate`."""

    key: ConsolidationKey
    apply_by: int
    """The target count by which it is applied (:meth:`ConsolidationPolicy.apply_by`)."""
    space: SampleSpace[P]
    positions: tuple[P, ...]
    anchor: tuple[P, ...]
    reservoir: tuple[P, ...]
    power: float
    speed: float
    confidence: float
    updates: tuple[int, ...]
    fresh: int
    folds: int
    refit: bool
    tested_refit: bool
    stands: StandSet[P] | None
    shakes: int
    partners: tuple[tuple[str, ...], ...] = ()
    """Per reservoir target, the other types it needed (:attr:`Learning.partners`)."""
    others: tuple[tuple[str, tuple[P, ...], float], ...] = ()
    """The fleet's other types: each one's name, current references and speed factor."""

    def floors(self) -> list[float] | None:
        """Per reservoir target, ``c(T)`` of the last arrival of the other types it
        needed, each from its closest current reference (0 for a target of this type
        alone; ``None`` when no target needed another type)."""
        need = [i for i, kinds in enumerate(self.partners) if kinds and kinds != ANY_VEHICLE]
        found = self._others_times(need)
        if found is None:
            return None
        times, column = found
        out = [0.0] * len(self.reservoir)
        for i in need:
            j = column[self.reservoir[i]]
            last = max((float(times[k][j]) for k in self.partners[i] if k in times), default=0.0)
            out[i] = last**self.power
        return out

    def ceilings(self) -> list[float] | None:
        """Per reservoir target that needed any one vehicle (partners
        :data:`ANY_VEHICLE`), ``c(T)`` of the first arrival of the other types, each
        from its closest current reference (``inf`` for the other targets; ``None`` when
        no target needed any one vehicle)."""
        need = [i for i, kinds in enumerate(self.partners) if kinds == ANY_VEHICLE]
        found = self._others_times(need)
        if found is None:
            return None
        times, column = found
        out = [math.inf] * len(self.reservoir)
        for i in need:
            j = column[self.reservoir[i]]
            out[i] = min(float(t[j]) for t in times.values()) ** self.power
        return out

    def _others_times(self, need: list[int]) -> tuple[dict[str, FloatArray], dict[P, int]] | None:
        """Each other type's time from its closest current reference to each distinct
        place of the reservoir targets ``need``, and each place's column; ``None`` for
        no such target or no other type."""
        if not need or not self.others:
            return None
        places = list(dict.fromkeys(self.reservoir[i] for i in need))
        times = {
            kind: np.asarray(self.space.cost_matrix(list(refs), places)).min(axis=0) / speed
            for kind, refs, speed in self.others
        }
        return times, {z: j for j, z in enumerate(places)}

    def solve(self) -> Consolidation[P]:
        """:func:`consolidate` on the copied inputs."""
        return consolidate(
            self.space,
            self.positions,
            self.anchor,
            self.reservoir,
            power=self.power,
            speed=self.speed,
            confidence=self.confidence,
            updates=self.updates,
            fresh=self.fresh,
            folds=self.folds,
            refit=self.refit,
            tested_refit=self.tested_refit,
            stands=self.stands,
            shakes=self.shakes,
            floors=self.floors(),
            ceilings=self.ceilings(),
        )


def move_pays(
    space: SampleSpace[P],
    positions: Sequence[P],
    mover: int,
    new: P,
    sample: Sequence[P],
    *,
    power: float,
    speed: float,
) -> bool:
    """Whether moving reference ``mover`` to ``new`` lowers the sample's mean cost.

    The empirical objective (11) of the fleet on ``sample`` (each target served by
    its closest reference) with the move against without it; an empty sample
    cannot judge, and the move is taken.

    Parameters
    ----------
    space : SampleSpace
        The space.
    positions : sequence
        The current references.
    mover : int
        The index of the reference that would move.
    new : position
        Where it would move.
    sample : sequence
        The targets that judge (the reservoir).
    power, speed : float
        As in :func:`consolidate`.
    """
    if not sample:
        return True
    counts: dict[P, int] = {}
    for z in sample:
        counts[z] = counts.get(z, 0) + 1
    targets = list(counts)
    weight = np.fromiter(counts.values(), dtype=np.float64, count=len(targets))
    costs = np.asarray(space.cost_matrix([*positions, new], targets), dtype=np.float64) / speed
    costs = costs**power
    p = len(positions)
    others = np.delete(costs[:p], mover, axis=0)
    rest = others.min(axis=0) if others.shape[0] else np.full(len(targets), np.inf)
    before = float(weight @ np.minimum(rest, costs[mover]))
    after = float(weight @ np.minimum(rest, costs[p]))
    return after < before


def _distinct(rows: IntArray, n_sites: int) -> IntArray:
    """``rows`` with repeats replaced by the next free row (references that coincide)."""
    taken: set[int] = set()
    out = rows.copy()
    for k, r in enumerate(rows.tolist()):
        while r in taken:
            r = (r + 1) % n_sites
        taken.add(r)
        out[k] = r
    return out


def best_fit(costs: FloatArray, weight: FloatArray, starts: list[IntArray]) -> IntArray:
    """The best local optimum for ``weight`` from each start and from greedy addition.

    The searches see only the targets of positive weight (a fold's left-out targets
    add exact zeros to every sum they would enter).
    """
    p = starts[0].size
    distinct = [
        s for k, s in enumerate(starts) if not any(np.array_equal(s, t) for t in starts[:k])
    ]
    seen, seen_weight = _weighed(costs, weight)
    seen = np.ascontiguousarray(seen)
    transposed = np.ascontiguousarray(seen.T)
    candidates = [fast_interchange(seen, seen_weight, s, transposed=transposed) for s in distinct]
    candidates.append(
        fast_interchange(seen, seen_weight, greedy(seen, seen_weight, p), transposed=transposed)
    )
    values = [_total(costs, weight, c) for c in candidates]
    return candidates[int(np.argmin(values))]


def priced_fit(
    plain: FloatArray, priced: FloatArray, weight: FloatArray, starts: list[IntArray], shakes: int
) -> IntArray:
    """The p-median fit of ``weight`` on the ``plain`` costs (:func:`best_fit`, then
    :func:`searched`), improved by the fast interchange on the ``priced`` costs (the
    last arrival of targets of several types) when they differ."""
    sites = searched(plain, weight, best_fit(plain, weight, starts), shakes)
    if priced is plain:
        return sites
    seen, seen_weight = _weighed(priced, weight)
    return fast_interchange(np.ascontiguousarray(seen), seen_weight, sites)


def _fold_fits(
    plain: FloatArray,
    priced: FloatArray,
    weight: FloatArray,
    parts: list[FloatArray],
    starts: list[IntArray],
) -> list[IntArray]:
    """:func:`priced_fit` of ``weight`` without each part, the parts solved side by side on
    threads (the kernels release the GIL; each solve is the same as alone)."""

    def fit(part: FloatArray) -> IntArray:
        return priced_fit(plain, priced, weight - part, starts, 0)

    workers = min(len(parts), os.cpu_count() or 1)
    if workers < 2:
        return [fit(part) for part in parts]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(fit, parts))


def searched(costs: FloatArray, weight: FloatArray, sites: IntArray, shakes: int) -> IntArray:
    """``sites`` improved by variable neighbourhood search (``shakes`` without gain in
    a row; 0: unchanged), over the targets of positive weight."""
    if shakes == 0:
        return sites
    seen, seen_weight = _weighed(costs, weight)
    return neighbourhood_search(seen, seen_weight, sites, shakes_without_gain=shakes)


def _weighed(costs: FloatArray, weight: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The columns of positive weight (the others add exact zeros to every sum); the
    arrays themselves, not a copy, when every weight is positive."""
    weighed = weight > 0.0
    if weighed.all():
        return costs, weight
    return np.compress(weighed, costs, axis=1), weight[weighed]


def _total(costs: FloatArray, weight: FloatArray, rows: IntArray) -> float:
    return float(weight @ costs[rows].min(axis=0))


def _pair(current: IntArray, chosen: IntArray) -> IntArray:
    """The chosen sites (a multiset) in vehicle order: a vehicle already on one keeps
    it while it has room, the others take the rest in ascending order."""
    room = Counter(chosen.tolist())
    out = []
    for r in current.tolist():
        keeps = room[r] > 0
        out.append(r if keeps else -1)
        room[r] -= keeps
    free = sorted(room.elements())
    for k, r in enumerate(out):
        if r < 0:
            out[k] = free.pop(0)
    return np.array(out, dtype=np.int64)


def _stand_rows(space: SampleSpace[P], stands: StandSet[P], references: Sequence[P]) -> IntArray:
    """Each reference's stand row (:func:`routing_svc.sa.stands.stand_assignment`)."""
    costs = np.asarray(space.cost_matrix(list(stands.positions), list(references)))
    return stand_assignment(costs.astype(np.float64), stands.capacities)


def _padded(rows: IntArray, size: int, n_sites: int) -> IntArray:
    """The distinct ``rows`` in order, then the lowest other rows up to ``size``."""
    kept = list(dict.fromkeys(rows.tolist()))[:size]
    taken = set(kept)
    rest = (r for r in range(n_sites) if r not in taken)
    return np.array([*kept, *(next(rest) for _ in range(size - len(kept)))], dtype=np.int64)
