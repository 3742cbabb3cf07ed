"""Posts (move-up): the best references for the available vehicles, against brute force
and by hand on the plane."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from routing_svc.sa import (
    ROUTING,
    Constant,
    EuclideanPlane,
    Fleet,
    FleetConfig,
    Status,
    Vehicle,
    VehicleState,
)
from routing_svc.sa.posts import choose_posts, match_posts
from routing_svc.types import PlanePosition as Pt

BUSY: VehicleState[Pt] = VehicleState(Status.BUSY)


def make_fleet(points: list[tuple[str, str, Pt]]) -> Fleet[Pt]:
    config = FleetConfig(objective=ROUTING, schedule=Constant(1.0))
    vehicles = [(Vehicle(vid, kind), p) for vid, kind, p in points]
    return Fleet.create(EuclideanPlane(side=30.0), vehicles, config)


@pytest.mark.parametrize("seed", range(6))
def test_chosen_posts_are_the_best_subset_of_the_references(seed: int) -> None:
    rng = np.random.default_rng(seed)
    costs = rng.exponential(10.0, size=(7, 40))
    for k in range(1, 8):
        chosen = choose_posts(costs, k)
        assert chosen.tolist() == sorted(set(chosen.tolist())) and chosen.size == k
        best = min(
            costs[list(subset)].min(axis=0).sum() for subset in itertools.combinations(range(7), k)
        )
        assert costs[chosen].min(axis=0).sum() == pytest.approx(best, rel=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_beyond_enumeration_the_posts_are_a_local_optimum_of_single_swaps(seed: int) -> None:
    costs = np.random.default_rng(seed).exponential(10.0, size=(12, 60))
    k = 5
    chosen = choose_posts(costs, k, exact_work=0)
    value = costs[chosen].min(axis=0).sum()
    for leave, enter in itertools.product(chosen.tolist(), range(12)):
        if enter in chosen:
            continue
        swapped = [enter if s == leave else s for s in chosen.tolist()]
        assert costs[swapped].min(axis=0).sum() >= value * (1 - 1e-9)
    assert value <= costs[choose_posts(costs, k)].min(axis=0).sum() * 1.1


def test_unreachable_references_are_chosen_last() -> None:
    costs = np.array([[math.inf, math.inf], [1.0, 5.0], [4.0, 2.0]])
    assert choose_posts(costs, 2).tolist() == [1, 2]


@pytest.mark.parametrize("seed", range(4))
def test_posts_are_matched_at_the_least_total_travel(seed: int) -> None:
    travel = np.random.default_rng(seed).uniform(0.0, 100.0, size=(5, 5))
    matched = match_posts(travel)
    assert sorted(matched.tolist()) == list(range(5))
    best = min(sum(travel[i, p[i]] for i in range(5)) for p in itertools.permutations(range(5)))
    assert travel[np.arange(5), matched].sum() == pytest.approx(best)


def test_every_vehicle_available_holds_its_own_reference() -> None:
    fleet = make_fleet([("a", "A", Pt(0.0, 0.0)), ("b", "A", Pt(10.0, 0.0))])
    fleet.set_states([("b", VehicleState(Status.AVAILABLE, Pt(10.0, 3.0)))])
    posts = fleet.posts()
    assert [(p.vehicle, p.reference_of, p.position, p.time) for p in posts] == [
        (0, 0, Pt(0.0, 0.0), 0.0),
        (1, 1, Pt(10.0, 0.0), 3.0),
    ]


def test_a_busy_vehicles_reference_is_taken_over_by_hand() -> None:
    # The references are the demand sample (no reservoir): one target at each.
    # a, at (0, 0), is busy; b waits at its reference (10, 0); c, whose reference
    # is (30, 0), drives at (2, 3). Two posts out of three, by hand:
    # {0, 10}: 0 + 0 + 20 = 20; {0, 30}: 0 + 10 + 0 = 10; {10, 30}: 10 + 0 + 0 = 10.
    # Of the two best, {10, 30} holds only the available vehicles' own references.
    fleet = make_fleet(
        [("a", "A", Pt(0.0, 0.0)), ("b", "A", Pt(10.0, 0.0)), ("c", "A", Pt(30.0, 0.0))]
    )
    fleet.set_states([("a", BUSY), ("c", VehicleState(Status.AVAILABLE, Pt(2.0, 3.0)))])
    posts = {p.vehicle: p for p in fleet.posts()}
    assert set(posts) == {1, 2}
    assert {p.position for p in posts.values()} == {Pt(10.0, 0.0), Pt(30.0, 0.0)}
    # b at (10, 0) stays (0) and c goes to (30, 0) (sqrt(28^2 + 3^2)), or b goes to
    # 30 (20) and c to 10 (sqrt(8^2 + 3^2)): 28.16 against 28.54.
    assert posts[1].reference_of == 1 and posts[1].time == 0.0
    assert posts[2].reference_of == 2 and posts[2].time == pytest.approx(math.hypot(28.0, 3.0))


def test_an_uncovered_reference_nearer_the_demand_is_held() -> None:
    # Demand at 0 (where the busy a waits) weighs more once c is far: from (2, 3),
    # c takes over a's reference, which the best pair {0, 10} includes.
    fleet = make_fleet(
        [("a", "A", Pt(0.0, 0.0)), ("b", "A", Pt(10.0, 0.0)), ("c", "A", Pt(12.0, 0.0))]
    )
    fleet.set_states([("a", BUSY), ("c", VehicleState(Status.AVAILABLE, Pt(2.0, 3.0)))])
    posts = {p.vehicle: p for p in fleet.posts()}
    # {0,10}: 0+0+2 = 2; {0,12}: 0+2+0 = 2; {10,12}: 10. Greedy opens 10 (10+0+2),
    # then 0 (gain 10) before 12 (gain 2): {0, 10}; b stays, c drives to (0, 0).
    assert posts[1].reference_of == 1 and posts[1].time == 0.0
    assert posts[2].reference_of == 0 and posts[2].time == pytest.approx(math.hypot(2.0, 3.0))
    assert fleet.state.positions == [Pt(0.0, 0.0), Pt(10.0, 0.0), Pt(12.0, 0.0)]


def test_posts_stay_within_each_type() -> None:
    fleet = make_fleet(
        [("a", "A", Pt(0.0, 0.0)), ("b", "B", Pt(1.0, 0.0)), ("c", "B", Pt(20.0, 0.0))]
    )
    fleet.set_states([("a", BUSY), ("b", BUSY)])
    (post,) = fleet.posts()
    # One B post: b's (1, 0) serves the three targets at 1 + 0 + 19, c's (20, 0) at
    # 20 + 19 + 0; a's (0, 0) would be better still, but it is not a B reference.
    assert (post.vehicle, post.reference_of, post.position, post.time) == (
        2,
        1,
        Pt(1.0, 0.0),
        19.0,
    )
    fleet.set_states([("c", VehicleState(Status.OFFLINE))])
    assert fleet.posts() == []
