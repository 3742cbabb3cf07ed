"""The shift test of who won each block (:meth:`ConsolidationPolicy.shares_moved`).

A demand can move where its cost does not grow; the winners of a block of targets then
fall on the vehicles in other shares than the references served of the reservoir they
were last fitted to. The tests compare the fleet's epochs with an independent reading of
its outcomes (the G test by ``scipy.stats.chi2``) and with hand-computed statistics.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

import pytest
from scipy.stats import chi2

from routing_svc.errors import InvalidInput
from routing_svc.network import RoadSpace
from routing_svc.sa import ConsolidationPolicy
from routing_svc.sa.consolidation import expected_shares
from tests.sa.test_consolidation import NET, consolidating_fleet, demand_stream

BLOCK = 250


@pytest.fixture(scope="module")
def space() -> RoadSpace:
    return RoadSpace(NET, cost="length")


def g_statistic(wins: Sequence[int], served: Sequence[int]) -> float:
    """``2 sum w ln(w / e)`` with ``e`` the block's size times the share of each vehicle's
    served count plus a half, written out again."""
    size = sum(wins)
    total = sum(served) + 0.5 * len(served)
    return 2.0 * sum(
        w * math.log(w / (size * (c + 0.5) / total))
        for w, c in zip(wins, served, strict=True)
        if w > 0
    )


def test_the_test_of_the_winners_by_hand() -> None:
    policy = ConsolidationPolicy()
    assert policy.share_alpha == 1e-9
    # a half added to each count: 300.5 and 100.5 of 401
    assert expected_shares([300, 100]) == pytest.approx([300.5 / 401, 100.5 / 401])
    # wins of 125 and 125 where 187.3 and 62.7 are expected:
    # G = 2 (125 ln(125 / 187.34) + 125 ln(125 / 62.66)) = 71.5 > 37.3, the quantile of
    # 1 - 1e-9 with one degree of freedom
    assert g_statistic([125, 125], [300, 100]) == pytest.approx(71.5, abs=0.1)
    assert chi2.isf(1e-9, 1) == pytest.approx(37.3, abs=0.05)
    assert policy.shares_moved([125, 125], [300, 100])
    assert not policy.shares_moved([190, 60], [300, 100])
    # the threshold is the chi-square quantile, checked against scipy.stats
    for wins, served in (
        ([40, 60, 150], [1000, 1000, 2000]),
        ([10, 10, 230], [1000, 1000, 2000]),
        ([0, 0, 250], [1300, 1300, 1400]),
        ([83, 83, 84], [1300, 1300, 1400]),
    ):
        for alpha in (1e-9, 1e-3, 0.5):
            moved = ConsolidationPolicy(share_alpha=alpha).shares_moved(wins, served)
            assert moved == (chi2.sf(g_statistic(wins, served), len(wins) - 1) < alpha)
    # vehicles at one place (a stand) share their wins and counts, whichever wins a tie
    assert policy.shares_moved([190, 0, 60], [0, 3000, 1000])
    assert not policy.shares_moved([190, 0, 60], [0, 3000, 1000], ["a", "a", "b"])
    assert policy.shares_moved([190, 0, 60], [0, 3000, 1000], ["a", "b", "c"])
    assert not policy.shares_moved([250, 0], [0, 4000], ["a", "a"])  # one place: no test
    # no test without its probability, or of one vehicle
    assert not ConsolidationPolicy(share_alpha=None).shares_moved([250, 0], [0, 4000])
    assert not policy.shares_moved([250], [4000])


def first_moved_block(outcomes: Sequence[Any], ids: Sequence[str], alpha: float) -> int | None:
    """From the outcomes alone: the winners of blocks of 250 targets, each begun at an
    accepted consolidation or at the end of the block before, and the first block end
    whose G test against the shares that consolidation served rejects at ``alpha``."""
    slot = {vid: i for i, vid in enumerate(ids)}
    served: Sequence[int] | None = None
    wins = [0] * len(ids)
    for outcome in outcomes:
        if served is not None:
            wins[slot[outcome.dispatch.moved]] += 1
            if sum(wins) == BLOCK:
                if chi2.sf(g_statistic(wins, served), len(ids) - 1) < alpha:
                    return int(outcome.target_number) + 1
                wins = [0] * len(ids)
        done = outcome.consolidation
        if done is not None and done.accepted:
            served, wins = done.updates, [0] * len(ids)
    return None


def moved_demand() -> tuple[list[Any], list[Any]]:
    """Targets round two hotspots, then round two others across the district."""
    xmin, ymin, xmax, ymax = NET.bounds
    dx, dy = xmax - xmin, ymax - ymin
    spread = 0.05 * math.hypot(dx, dy)
    _, before = demand_stream(
        11, 3000, centres=[(xmin + 0.2 * dx, ymin + 0.3 * dy), (xmin + 0.3 * dx, ymin + 0.8 * dy)],
        spread=spread,
    )  # fmt: skip
    _, after = demand_stream(
        12, 2000, centres=[(xmin + 0.8 * dx, ymin + 0.7 * dy), (xmin + 0.7 * dx, ymin + 0.2 * dy)],
        spread=spread,
    )  # fmt: skip
    return before, after


def test_winners_in_other_shares_start_a_new_epoch(space: RoadSpace) -> None:
    """The cost test is off (a ratio never reached): only the winners show the move."""
    before, after = moved_demand()
    runs = {}
    for alpha in (1e-9, None):
        policy = ConsolidationPolicy(shift_ratio=1e9, hasten=None, share_alpha=alpha)
        fleet = consolidating_fleet(space, policy=policy)
        outcomes = [fleet.observe(z) for z in before]
        learning = fleet.state.learning
        assert learning is not None and learning.epoch == 0  # no false alarm
        outcomes += [fleet.observe(z) for z in after]
        runs[alpha] = (fleet, outcomes)
    fleet, outcomes = runs[1e-9]
    ids = [v.id for v in fleet.vehicles]
    expected = first_moved_block(outcomes, ids, 1e-9)
    # the move shows in the first block that holds 250 targets of the new demand
    assert expected is not None and 3000 < expected <= 3000 + 2 * BLOCK
    learning = fleet.state.learning
    assert learning is not None and learning.epoch == expected
    assert learning.fitted > 0  # consolidations of the new epoch fitted the references
    first_after = next(o.consolidation for o in outcomes[expected:] if o.consolidation is not None)
    assert first_after is not None and first_after.sample == BLOCK + ConsolidationPolicy().first
    unseen, _ = runs[None]
    kept = unseen.state.learning
    assert kept is not None and kept.epoch == 0


def test_a_demand_that_stays_starts_no_epoch_by_its_winners(space: RoadSpace) -> None:
    _, stream = demand_stream(13, 8000)
    policy = ConsolidationPolicy(shift_ratio=1e9, hasten=None)
    fleet = consolidating_fleet(space, n=6, policy=policy)
    outcomes = [fleet.observe(z) for z in stream]
    learning = fleet.state.learning
    assert learning is not None and learning.epoch == 0
    ids = [v.id for v in fleet.vehicles]
    assert first_moved_block(outcomes, ids, 1e-9) is None
    # while the same reading at a false alarm of one in two finds blocks it would take
    assert first_moved_block(outcomes, ids, 0.5) is not None


def test_the_winners_block_survives_a_snapshot(space: RoadSpace) -> None:
    _, stream = demand_stream(14, 3000)
    policy = ConsolidationPolicy(shift_ratio=1e9, hasten=None)
    whole = consolidating_fleet(space, policy=policy)
    outcomes = [whole.observe(z) for z in stream]
    cut = 2345
    first = consolidating_fleet(space, policy=policy)
    for z in stream[:cut]:
        first.observe(z)
    learning = first.state.learning
    assert learning is not None and learning.served is not None and 0 < learning.won < BLOCK
    saved = json.loads(json.dumps(first.snapshot()))
    assert saved["learning"]["wins"] == learning.wins
    assert sum(saved["learning"]["served"]) == learning.fitted
    restored = consolidating_fleet(space, policy=policy)
    restored.restore(saved)
    for z, out in zip(stream[cut:], outcomes[cut:], strict=True):
        assert restored.observe(z) == out
    assert json.dumps(restored.snapshot()) == json.dumps(whole.snapshot())
    # winners that do not match the fleet's vehicles are refused
    for wrong in ({"wins": [1, 2]}, {"served": [1, 2, 3]}, {"served": None, "wins": [1] * 4}):
        bad = {**saved, "learning": {**saved["learning"], **wrong}}
        with pytest.raises(InvalidInput):
            consolidating_fleet(space, policy=policy).restore(bad)
