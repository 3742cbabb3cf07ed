"""Step counters that start from a prior sample (``FleetConfig.prior_counts``)."""

from __future__ import annotations

import pytest

from routing_svc.errors import InvalidInput
from routing_svc.sa import (
    ROUTING,
    Counting,
    EuclideanPlane,
    Fleet,
    FleetConfig,
    InverseScaling,
    Vehicle,
    prior_counts,
)
from routing_svc.types import PlanePosition

SPACE = EuclideanPlane(side=10.0)
STARTS = [PlanePosition(1.0, 1.0), PlanePosition(9.0, 1.0), PlanePosition(5.0, 9.0)]


def test_each_sample_target_counts_for_the_vehicle_that_reaches_it_first() -> None:
    sample = [
        PlanePosition(0.0, 0.0),  # a (distance 1.4)
        PlanePosition(2.0, 2.0),  # a
        PlanePosition(8.0, 0.0),  # b
        PlanePosition(5.0, 8.0),  # c
        PlanePosition(5.0, 1.0),  # a and b at 4.0: the lower index wins
    ]
    assert prior_counts(SPACE, STARTS, [1.0, 1.0, 1.0], sample) == (3, 1, 1)
    # b twice as fast: (5, 1) is now b's (2 s against 4 s); (2, 2) stays a's (1.4 s < 3.5 s)
    assert prior_counts(SPACE, STARTS, [1.0, 2.0, 1.0], sample) == (2, 2, 1)
    assert prior_counts(SPACE, STARTS, [1.0, 1.0, 1.0], []) == (0, 0, 0)


def config(counting: Counting, prior: tuple[int, ...]) -> FleetConfig:
    return FleetConfig(
        objective=ROUTING,
        schedule=InverseScaling(2.0, 1.0),
        counting=counting,
        prior_counts=prior,
    )


def test_the_step_counter_starts_at_the_prior_count() -> None:
    vehicles = [(Vehicle(f"v{i}"), p) for i, p in enumerate(STARTS)]
    fleet = Fleet.create(SPACE, vehicles, config(Counting.VEHICLE, (3, 0, 7)))
    assert [fleet.step_size(i) for i in range(3)] == [2.0 / 4, 2.0 / 1, 2.0 / 8]
    pooled = Fleet.create(SPACE, vehicles, config(Counting.FLEET, (3, 0, 7)))
    assert [pooled.step_size(i) for i in range(3)] == [2.0 / 11] * 3
    outcome = fleet.observe(PlanePosition(1.0, 2.0), None)
    assert outcome.step_size == 2.0 / 4  # v0 moved with k = 3
    assert fleet.step_size(0) == 2.0 / 5 and fleet.state.updates == [1, 0, 0]
    data = config(Counting.VEHICLE, (3, 0, 7)).to_dict()
    assert FleetConfig.from_dict(data).prior_counts == (3, 0, 7)
    assert "prior_counts" not in config(Counting.VEHICLE, ()).to_dict()


@pytest.mark.parametrize("prior", [(1, 2), (1, -1, 0)])
def test_prior_counts_must_fit_the_fleet(prior: tuple[int, ...]) -> None:
    vehicles = [(Vehicle(f"v{i}"), p) for i, p in enumerate(STARTS)]
    with pytest.raises(InvalidInput, match="prior_counts"):
        Fleet.create(SPACE, vehicles, config(Counting.VEHICLE, prior))
