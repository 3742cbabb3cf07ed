"""Snapping coordinates to network positions, against a brute-force shapely search."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from routing_svc.errors import InvalidInput, OffNetwork
from routing_svc.network import RoadSpace, Snapper
from tests.network.conftest import NetCase


def edge_lines(case: NetCase) -> list[shapely.LineString]:
    net = case.network
    return [
        shapely.LineString(net.shape_xy[net.shape_offsets[i] : net.shape_offsets[i + 1]])
        for i in range(net.n_edges)
    ]


def test_snap_finds_the_nearest_edge_and_rescales_the_offset(case: NetCase) -> None:
    net = case.network
    lines = edge_lines(case)
    rng = np.random.default_rng(31)
    xmin, ymin, xmax, ymax = net.bounds
    xs = rng.uniform(xmin - 50, xmax + 50, 400)
    ys = rng.uniform(ymin - 50, ymax + 50, 400)
    snapped = Snapper(net).snap_xy(xs, ys)
    assert len(snapped) == 400
    for x, y, position in zip(xs, ys, snapped, strict=True):
        point = shapely.Point(x, y)
        distances = np.array([line.distance(point) for line in lines])
        line = lines[position.edge]
        assert line.distance(point) == pytest.approx(distances.min(), abs=1e-9)
        assert position.edge == int(np.flatnonzero(distances <= distances.min())[0])
        expected = line.project(point) * net.length[position.edge] / line.length
        assert position.offset == pytest.approx(min(expected, net.length[position.edge]), abs=1e-9)
        assert 0.0 <= position.offset <= net.length[position.edge]


def test_points_on_the_network_snap_back_to_themselves(case: NetCase) -> None:
    space = RoadSpace(case.network, either_way=False)
    rng = np.random.default_rng(32)
    positions = case.random_positions(rng, 200)
    points = np.array([space.xy(p) for p in positions])
    snapped = Snapper(case.network).snap_xy(points[:, 0], points[:, 1], max_distance=1.0)
    for original, back in zip(positions, snapped, strict=True):
        assert np.hypot(*np.subtract(space.xy(back), space.xy(original))) < 1e-6


def test_snap_lonlat_uses_the_network_projection(drt_case: NetCase) -> None:
    space = RoadSpace(drt_case.network, either_way=False)
    rng = np.random.default_rng(33)
    positions = drt_case.random_positions(rng, 100)
    lonlat = np.array([space.lonlat(p) for p in positions])
    snapped = Snapper(drt_case.network).snap_lonlat(lonlat[:, 0], lonlat[:, 1], max_distance=1.0)
    for original, back in zip(positions, snapped, strict=True):
        assert np.hypot(*np.subtract(space.xy(back), space.xy(original))) < 1e-6


def test_far_points_are_off_the_network(drt_case: NetCase) -> None:
    snapper = Snapper(drt_case.network)
    xmin, ymin, xmax, ymax = drt_case.network.bounds
    with pytest.raises(OffNetwork, match="farther than 100"):
        snapper.snap_xy([xmin + 10, xmax + 5000], [ymin + 10, ymax + 5000], max_distance=100.0)
    assert len(snapper.snap_xy([xmax + 5000], [ymax + 5000])) == 1


@pytest.mark.parametrize(
    ("xs", "ys", "options"),
    [
        ([float("nan")], [0.0], {}),
        ([0.0], [float("inf")], {}),
        ([0.0, 1.0], [0.0], {}),
        (["a"], [0.0], {}),
        ([0.0], [0.0], {"max_distance": 0.0}),
        ([0.0], [0.0], {"max_distance": float("nan")}),
    ],
)
def test_bad_coordinates_are_invalid_input(
    drt_case: NetCase, xs: list[object], ys: list[object], options: dict[str, float]
) -> None:
    with pytest.raises(InvalidInput):
        Snapper(drt_case.network).snap_xy(xs, ys, **options)  # type: ignore[arg-type]


def test_bad_geographic_coordinates(drt_case: NetCase, oneway_case: NetCase) -> None:
    with pytest.raises(InvalidInput):
        Snapper(drt_case.network).snap_lonlat([13.5], [95.0])
    with pytest.raises(InvalidInput, match="projection"):
        Snapper(oneway_case.network).snap_lonlat([13.5], [52.4])


def test_empty_input_gives_no_positions(drt_case: NetCase) -> None:
    assert Snapper(drt_case.network).snap_xy([], []) == []
