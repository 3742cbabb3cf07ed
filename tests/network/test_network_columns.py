"""The search columns kept between searches equal the columns built from scratch."""

from __future__ import annotations

import numpy as np
import pytest

from routing_svc.errors import InvalidInput
from routing_svc.network.columns import SearchColumns
from routing_svc.network.search import fleet_columns
from routing_svc.network.twins import twin_columns
from routing_svc.types import NetPosition
from tests.network.conftest import NetCase


def _from_scratch(
    case: NetCase, positions: list[NetPosition], either_way: bool
) -> tuple[np.ndarray, np.ndarray]:
    """The columns of the whole list, twins by the numpy formulation of ``twin_columns``."""
    edges, offsets = fleet_columns(positions)
    if either_way:
        twin_edges, twin_offsets = twin_columns(case.network, edges, offsets)
        edges = np.concatenate((edges, twin_edges))
        offsets = np.concatenate((offsets, twin_offsets))
    return edges, offsets


@pytest.mark.parametrize("either_way", [True, False])
def test_columns_follow_every_change_of_the_list(case: NetCase, either_way: bool) -> None:
    """2,000 rounds of moving 0 to 3 positions of a 40-vehicle list in place, with
    ends of edges, integer offsets and numpy edge indices among the new positions."""
    rng = np.random.default_rng(31)
    net = case.network
    columns = SearchColumns(net, either_way=either_way)
    positions = case.random_positions(rng, 40)
    for _ in range(2000):
        for i in rng.choice(40, size=int(rng.integers(0, 4)), replace=False):
            (fresh,) = case.random_positions(rng, 1)
            kind = rng.integers(4)
            if kind == 1:
                fresh = NetPosition(fresh.edge, float(net.length[fresh.edge]))
            elif kind == 2:
                fresh = NetPosition(fresh.edge, 0)
            elif kind == 3:
                fresh = NetPosition(np.int64(fresh.edge), fresh.offset)  # type: ignore[arg-type]
            positions[i] = fresh
        edges, offsets = columns.of(positions)
        expected_edges, expected_offsets = _from_scratch(case, positions, either_way)
        np.testing.assert_array_equal(edges, expected_edges)
        np.testing.assert_array_equal(offsets, expected_offsets)  # bit for bit


def test_columns_of_several_lists_and_a_list_that_changed_length(drt_case: NetCase) -> None:
    rng = np.random.default_rng(32)
    columns = SearchColumns(drt_case.network, either_way=True, capacity=2)
    lists = [drt_case.random_positions(rng, n) for n in (5, 7, 9)]
    for _ in range(3):
        for positions in lists:
            np.testing.assert_array_equal(
                columns.of(positions)[1], _from_scratch(drt_case, positions, True)[1]
            )
    lists[0].append(drt_case.random_positions(rng, 1)[0])
    assert columns.of(lists[0])[0].shape == (12,)


def test_a_bad_new_position_is_rejected_every_time(drt_case: NetCase) -> None:
    rng = np.random.default_rng(33)
    columns = SearchColumns(drt_case.network, either_way=True)
    positions = drt_case.random_positions(rng, 4)
    columns.of(positions)
    positions[2] = NetPosition(1.5, 3.0)  # type: ignore[arg-type]
    for _ in range(2):
        with pytest.raises(InvalidInput):
            columns.of(positions)
