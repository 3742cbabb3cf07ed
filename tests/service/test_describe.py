"""``NetworkEntry.describe``: the place an answer names, kept for the places that repeat."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

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
