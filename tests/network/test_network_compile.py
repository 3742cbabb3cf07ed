"""Compiling SUMO networks: edge set, connections, attributes, layout, projection."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from routing_svc.errors import InvalidInput, InvalidNetwork
from routing_svc.network import CompiledNetwork, GeoProjection, load_network
from routing_svc.network.layout import hilbert_keys
from tests.network.conftest import DRT_NET, NetCase
from tests.network.reference import NxReference


def arcs_of(network: CompiledNetwork) -> set[tuple[str, str]]:
    ids = network.edge_ids
    tails = np.repeat(np.arange(network.n_edges), np.diff(network.fwd_indptr))
    return {(ids[a], ids[b]) for a, b in zip(tails, network.fwd_indices, strict=True)}


def test_edges_are_the_largest_strong_component(case: NetCase) -> None:
    assert set(case.network.edge_ids) == set(case.reference.graph.nodes)
    assert len(case.network.edge_ids) == case.network.n_edges


def test_reduction_reports_what_was_dropped(case: NetCase) -> None:
    reduction = case.network.reduction
    assert reduction.usable_edges == case.reference.usable_edges
    assert reduction.kept_edges == case.network.n_edges
    assert reduction.dropped_edges == reduction.usable_edges - reduction.kept_edges


def test_one_way_net_drops_many_edges(oneway_case: NetCase) -> None:
    reduction = oneway_case.network.reduction
    assert reduction.dropped_edges > 50
    assert reduction.components > 2
    pairs = set(zip(oneway_case.network.edge_from, oneway_case.network.edge_to, strict=True))
    one_way = [p for p in pairs if (p[1], p[0]) not in pairs]
    assert len(one_way) > 100


def test_arcs_are_the_allowed_connections(case: NetCase) -> None:
    assert arcs_of(case.network) == set(case.reference.graph.edges)


def test_reverse_csr_is_the_transpose(case: NetCase) -> None:
    net = case.network
    heads = np.repeat(np.arange(net.n_edges), np.diff(net.rev_indptr))
    reverse = {
        (net.edge_ids[b], net.edge_ids[a]) for a, b in zip(heads, net.rev_indices, strict=True)
    }
    assert reverse == arcs_of(net)


def test_lengths_speeds_and_shapes_match_sumolib(case: NetCase) -> None:
    net, ref = case.network, case.reference
    for i, edge_id in enumerate(net.edge_ids):
        node = ref.graph.nodes[edge_id]
        assert net.length[i] == node["length"]
        assert net.speed[i] == node["speed"]
        shape = net.shape_xy[net.shape_offsets[i] : net.shape_offsets[i + 1]]
        np.testing.assert_array_equal(shape, np.array(node["shape"]))
    lo = net.shape_xy.min(axis=0)
    hi = net.shape_xy.max(axis=0)
    assert net.bounds == (lo[0], lo[1], hi[0], hi[1])


def test_arrays_are_read_only(drt_case: NetCase) -> None:
    for array in drt_case.network.arrays().values():
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 0


def test_other_vehicle_class_gives_its_own_graph(drt_case: NetCase, network_cache: Path) -> None:
    bicycle = load_network(DRT_NET, vclass="bicycle", cache_dir=network_cache)
    reference = NxReference(DRT_NET, vclass="bicycle")
    assert bicycle.vclass == "bicycle"
    assert set(bicycle.edge_ids) == set(reference.graph.nodes)
    assert arcs_of(bicycle) == set(reference.graph.edges)
    assert set(bicycle.edge_ids) != set(drt_case.network.edge_ids)


def test_unknown_vehicle_class_is_rejected(network_cache: Path) -> None:
    with pytest.raises(InvalidInput, match="vehicle class"):
        load_network(DRT_NET, vclass="hovercraft", cache_dir=network_cache)


def test_network_without_usable_edges_is_invalid(tmp_path: Path) -> None:
    path = tmp_path / "rail.net.xml"
    path.write_text(
        '<net version="1.9"><location netOffset="0,0" convBoundary="0,0,100,0" '
        'origBoundary="0,0,100,0" projParameter="!"/>'
        '<edge id="a" from="j0" to="j1"><lane id="a_0" index="0" allow="rail" speed="10" '
        'length="100" shape="0,0 100,0"/></edge>'
        '<junction id="j0" type="dead_end" x="0" y="0" incLanes="" intLanes="" shape="0,0"/>'
        '<junction id="j1" type="dead_end" x="100" y="0" incLanes="a_0" intLanes="" '
        'shape="100,0"/></net>'
    )
    with pytest.raises(InvalidNetwork, match="no edge open"):
        load_network(path, cache_dir=tmp_path / "cache")


ONE_EDGE = (
    '<net version="1.9"><location netOffset="0,0" convBoundary="0,0,100,0" '
    'origBoundary="0,0,100,0" projParameter="!"/>'
    '<edge id="a" from="j0" to="{to}"><lane id="a_0" index="0" speed="10" '
    'length="100" shape="0,0 100,0"/></edge>'
    '<junction id="j0" type="priority" x="0" y="0" incLanes="{inc}" intLanes="" shape="0,0"/>'
    "{j1}{connection}</net>"
)


def test_a_network_without_a_loop_is_invalid(tmp_path: Path) -> None:
    path = tmp_path / "line.net.xml"
    j1 = (
        '<junction id="j1" type="dead_end" x="100" y="0" incLanes="a_0" intLanes="" shape="100,0"/>'
    )
    path.write_text(ONE_EDGE.format(to="j1", inc="", j1=j1, connection=""))
    with pytest.raises(InvalidNetwork, match="no loop of edges open to vehicle class"):
        load_network(path, cache_dir=tmp_path / "cache")
    # SUMO's own example of a lone junction: four ways in, four ways out, no way back
    sumo_home = Path(__import__("sumo").SUMO_HOME)
    rilsa = sumo_home / "tools/sumolib/scenario/scenarios/RealWorld/RiLSA_example4/net.net.xml"
    with pytest.raises(InvalidNetwork, match="one edge, among 8"):
        load_network(rilsa, cache_dir=tmp_path / "cache")


def test_one_edge_that_leads_back_to_itself_is_a_loop(tmp_path: Path) -> None:
    path = tmp_path / "ring.net.xml"
    connection = '<connection from="a" to="a" fromLane="0" toLane="0" dir="t" state="M"/>'
    path.write_text(ONE_EDGE.format(to="j0", inc="a_0", j1="", connection=connection))
    network = load_network(path, cache_dir=tmp_path / "cache")
    assert network.edge_ids == ("a",)
    assert network.fwd_indices.tolist() == [0]


def test_inconsistent_arrays_are_rejected(drt_case: NetCase) -> None:
    net = drt_case.network
    fields = {name: getattr(net, name) for name in CompiledNetwork.__dataclass_fields__}
    fields.pop("edge_index")
    bad_indices = net.rev_indices.copy()
    bad_indices[0] = net.n_edges
    with pytest.raises(InvalidNetwork, match="out of range"):
        CompiledNetwork(**{**fields, "rev_indices": bad_indices})
    swapped = net.rev_indices.copy()
    swapped[[0, -1]] = swapped[[-1, 0]]
    with pytest.raises(InvalidNetwork, match="reverse"):
        CompiledNetwork(**{**fields, "rev_indices": swapped})


def test_edges_are_numbered_along_a_hilbert_curve(drt_case: NetCase) -> None:
    net = drt_case.network
    starts = net.shape_xy[net.shape_offsets[:-1]]
    ends = net.shape_xy[net.shape_offsets[1:] - 1]
    steps = np.hypot(*np.diff((starts + ends) / 2, axis=0).T)
    extent = max(net.bounds[2] - net.bounds[0], net.bounds[3] - net.bounds[1])
    # consecutive edges are close on the map: the median step is tiny against the extent
    assert np.median(steps) < extent / 50


def test_hilbert_keys_walk_a_grid_cell_by_cell() -> None:
    bits = 4
    x, y = np.meshgrid(np.arange(16), np.arange(16))
    keys = hilbert_keys(x.ravel(), y.ravel(), bits=bits)
    assert sorted(keys.tolist()) == list(range(256))
    order = np.argsort(keys)
    steps = np.abs(np.diff(x.ravel()[order])) + np.abs(np.diff(y.ravel()[order]))
    assert (steps == 1).all()


# (lon, lat) -> UTM (easting, northing), computed with PROJ 9.5.1 (pyproj.Proj(proj)(lon, lat)).
UTM33 = "+proj=utm +zone=33 +ellps=WGS84 +datum=WGS84 +units=m +no_defs"
UTM32 = "+proj=utm +zone=32 +ellps=WGS84 +datum=WGS84 +units=m +no_defs"
UTM32S = "+proj=utm +zone=32 +south +ellps=WGS84 +datum=WGS84 +units=m +no_defs"
PROJ_REFERENCE = [
    (UTM33, 13.5, 52.44, 398039.8165172116, 5811036.209040895),
    (UTM33, 16.234, 47.1, 593639.8565943894, 5217015.580251811),
    (UTM33, 9.7, 50.8, 126611.8354813687, 5640984.802803064),
    (UTM32, 9.7, 50.8, 549329.3387653036, 5627818.0394819295),
    (UTM32S, 10.234, -47.1, 593639.856594388, 4782984.41974819),
    (UTM32S, 7.5, -33.9, 361310.10605704377, 6247919.038651002),
]


@pytest.mark.parametrize(("proj", "lon", "lat", "easting", "northing"), PROJ_REFERENCE)
def test_utm_projection_matches_proj(
    proj: str, lon: float, lat: float, easting: float, northing: float
) -> None:
    projection = GeoProjection.parse(proj, (-100.0, 200.0))
    x, y = projection.to_xy(lon, lat)
    assert abs(x - (easting - 100.0)) < 1e-6
    assert abs(y - (northing + 200.0)) < 1e-6
    back_lon, back_lat = projection.to_lonlat(x, y)
    assert abs(back_lon - lon) < 1e-10
    assert abs(back_lat - lat) < 1e-10


def test_network_projection_is_read(drt_case: NetCase) -> None:
    projection = drt_case.network.projection
    assert projection is not None
    assert (projection.utm_zone, projection.south) == (33, False)
    assert (projection.offset_x, projection.offset_y) == (-398790.46, -5809246.45)
    lon, lat = projection.to_lonlat(np.array([0.0, 2628.33]), np.array([0.0, 3333.57]))
    # convBoundary corners lie inside SUMO's origBoundary (13.4539..13.5757, 52.4244..52.4598)
    assert (lon > 13.44).all() and (lon < 13.59).all()
    assert (lat > 52.41).all() and (lat < 52.47).all()


def test_unsupported_projection_refuses_to_convert() -> None:
    projection = GeoProjection.parse("+proj=merc +ellps=WGS84", (0.0, 0.0))
    assert not projection.supported
    with pytest.raises(InvalidInput, match="not supported"):
        projection.to_xy(1.0, 2.0)


def test_generated_net_has_no_projection(oneway_case: NetCase) -> None:
    assert oneway_case.network.projection is None
