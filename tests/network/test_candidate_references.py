"""The candidate references a consolidation chooses from, against sumolib's connections.

The reference builds the set from the networkx edge graph of
:class:`tests.network.reference.NxReference`: the given positions, the sample's targets
on edges it observes twice or more, and the ends of the sample's edges and of their
predecessors in that graph.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from routing_svc.network import RoadSpace
from routing_svc.types import NetPosition
from tests.network.conftest import NetCase


def reference_candidates(case: NetCase, sample: list[NetPosition]) -> set[tuple[str, float]]:
    """``(edge id, offset)`` of every candidate besides the given positions."""
    graph = case.reference.graph
    counts = Counter(case.ids(z)[0] for z in sample)
    shared = {case.ids(z) for z in sample if counts[case.ids(z)[0]] >= 2}
    edges = set(counts) | {q for e in counts for q in graph.predecessors(e)}
    return shared | {(e, float(graph.nodes[e]["length"])) for e in edges}


def test_candidates_match_the_networkx_reference(case: NetCase, space: RoadSpace) -> None:
    rng = np.random.default_rng(41)
    singles = case.random_positions(rng, 30)
    pairs = case.random_positions(rng, 10)
    shared_edge = [NetPosition(z.edge, z.offset / 2.0) for z in pairs]
    sample = [*singles, *pairs, *shared_edge, singles[0], singles[0]]
    fixed = case.random_positions(rng, 4)
    got = space.candidate_references(sample, fixed)
    assert got[:4] == fixed
    assert len(set(got)) == len(got)
    rest = {case.ids(z) for z in got[4:]}
    expected = reference_candidates(case, sample) - {case.ids(z) for z in fixed}
    assert {(e, round(s, 6)) for e, s in rest} == {(e, round(s, 6)) for e, s in expected}
    # a target alone on its edge is not offered; one observed twice is
    alone = [z for z in singles[1:] if sum(y.edge == z.edge for y in sample) == 1]
    assert alone
    assert not set(alone) & set(got[4:]) - set(fixed)
    assert singles[0] in got


def test_a_target_alone_on_its_edge_yields_the_junction_it_starts_from(
    case: NetCase, space: RoadSpace
) -> None:
    target = case.random_positions(np.random.default_rng(42), 1)[0]
    got = space.candidate_references([target], [])
    graph = case.reference.graph
    edge = case.ids(target)[0]
    before = {(q, float(graph.nodes[q]["length"])) for q in graph.predecessors(edge)}
    assert before
    assert target not in got
    assert before <= {case.ids(z) for z in got}
    for z in got:
        if case.ids(z) in before:
            assert space.path_cost(z, target) == pytest.approx(target.offset)
