"""Points on edge shapes and their geographic coordinates, against shapely and the
array form of the projection."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from routing_svc.network.snapping import point_on_edge
from tests.network.conftest import NetCase


def test_point_on_edge_matches_shapely_interpolation(case: NetCase) -> None:
    net = case.network
    rng = np.random.default_rng(41)
    for edge in rng.integers(net.n_edges, size=300):
        line = shapely.LineString(
            net.shape_xy[net.shape_offsets[edge] : net.shape_offsets[edge + 1]]
        )
        for share in (0.0, float(rng.uniform()), 1.0):
            offset = share * float(net.length[edge])
            expected = line.interpolate(share * line.length)
            x, y = point_on_edge(net, int(edge), offset)
            assert x == pytest.approx(expected.x, abs=1e-6)
            assert y == pytest.approx(expected.y, abs=1e-6)


def test_one_point_projects_exactly_as_in_an_array(drt_case: NetCase) -> None:
    projection = drt_case.network.projection
    assert projection is not None and projection.supported
    rng = np.random.default_rng(42)
    xs, ys = rng.uniform(-3000, 6000, 200), rng.uniform(-3000, 6000, 200)
    lon, lat = projection.to_lonlat(xs, ys)
    points = [projection.point_to_lonlat(float(x), float(y)) for x, y in zip(xs, ys, strict=True)]
    assert [p[0] for p in points] == lon.tolist()
    assert [p[1] for p in points] == lat.tolist()
    back_x, back_y = projection.to_xy(lon, lat)
    assert np.abs(back_x - xs).max() < 1e-6 and np.abs(back_y - ys).max() < 1e-6
