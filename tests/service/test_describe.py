"""``NetworkEntry.describe``: the place an answer names, kept for the places that repeat."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from routing_svc.errors import InvalidInput
from routing_svc.network import RoadSpace, Snapper
from routing_svc.network.snapping import point_on_edge
from routing_svc.service import networks
from routing_svc.service.networks import NetworkEntry
from routing_svc.types import NetPosition
from tests.helpers import DRT, NET, edge


def test_descriptions_are_the_places_and_each_answer_owns_its_copy(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(networks, "DESCRIBED_PLACES", 8)
    entry = NetworkEntry("drt", "drt", Path(DRT), NET, Snapper(NET))
    rng = np.random.default_rng(5)
    places = [
        NetPosition(int(e), float(rng.uniform(0.0, NET.length[e])))
        for e in rng.choice(NET.n_edges, size=20, replace=False)
    ]
    for _ in range(3):  # described again (kept, and after the store was emptied)
        for place in places:
            got = entry.describe(place)
            x, y = point_on_edge(NET, place.edge, place.offset)
            lon, lat = RoadSpace(NET).lonlat(place)
            assert got == {
                "edge": edge(place.edge),
                "offset": place.offset,
                "x": x,
                "y": y,
                "lon": lon,
                "lat": lat,
            }
            got["edge"] = "changed by its reader"
            assert entry.describe(place)["edge"] == edge(place.edge)
            assert len(entry._described) <= 8


def _bits(described: dict[str, object]) -> dict[str, object]:
    return {k: float.hex(v) if isinstance(v, float) else v for k, v in described.items()}


@pytest.mark.parametrize("projected", [True, False])
def test_places_described_together_are_each_described_alone_bit_for_bit(projected: bool) -> None:
    net = NET if projected else dataclasses.replace(NET, projection=None)
    entry = NetworkEntry("drt", "drt", Path(DRT), net, Snapper(NET))
    rng = np.random.default_rng(6)
    edges = rng.integers(0, NET.n_edges, size=3_000)
    places = [NetPosition(int(e), float(rng.uniform(0.0, NET.length[e]))) for e in edges]
    places += [NetPosition(int(e), 0.0) for e in edges[:50]]  # edge ends
    places += [NetPosition(int(e), float(NET.length[e])) for e in edges[:50]]
    together = entry.describe_many(places)
    assert [_bits(d) for d in together] == [_bits(entry.describe(p)) for p in places]
    assert {len(d) for d in together} == {6 if projected else 4}
    assert entry.describe_many([]) == []


@pytest.mark.parametrize(
    "place",
    [NetPosition(-1, 0.0), NetPosition(NET.n_edges, 0.0), NetPosition(0, -1.0)],
)
def test_a_place_off_the_network_is_refused_when_described_together(place: NetPosition) -> None:
    entry = NetworkEntry("drt", "drt", Path(DRT), NET, Snapper(NET))
    with pytest.raises(InvalidInput, match="position 1"):
        entry.describe_many([NetPosition(0, 0.0), place])
