"""An independent reference for the road-network code: sumolib + networkx.

The edge graph is rebuilt here straight from sumolib's connections (lane by
lane, checking the from-lane, to-lane and connection permissions), its
largest strongly connected component is found with networkx, and costs are
computed with networkx's Dijkstra on a graph whose labels mean something
else than in the package: the cost from the *start* of an edge to the
target (the package labels the *end* of an edge).

Cost from a vehicle at ``(e, s)`` to a target at ``(t, s_t)``:
``(s_t - s) * rate[t]`` when ``e == t`` and ``s <= s_t``; otherwise
``(L[e] - s) * rate[e] + min over successors y of e of start_cost(y)``, where
``start_cost`` is the shortest cost from the start of an edge through whole
edges to the start of ``t`` plus ``s_t * rate[t]``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import networkx as nx
import numpy as np
import sumolib

TARGET = "__target__"


class NxReference:
    """The edge graph of a SUMO network for one vehicle class, in networkx."""

    def __init__(self, path: Path, *, vclass: str = "passenger") -> None:
        net = sumolib.net.readNet(str(path), withInternal=False, withConnections=True)
        usable = nx.DiGraph()
        for edge in net.getEdges():
            if edge.getFunction() == "internal" or not edge.allows(vclass):
                continue
            lanes = [lane for lane in edge.getLanes() if lane.allows(vclass)]
            usable.add_node(
                edge.getID(),
                length=edge.getLength(),
                speed=max(lane.getSpeed() for lane in lanes),
                shape=edge.getShape(),
            )
        for edge in net.getEdges():
            if edge.getID() not in usable:
                continue
            for to_edge, connections in edge.getOutgoing().items():
                if to_edge.getID() not in usable:
                    continue
                if any(
                    c.getFromLane().allows(vclass)
                    and c.getToLane().allows(vclass)
                    and c.allows(vclass)
                    for c in connections
                ):
                    usable.add_edge(edge.getID(), to_edge.getID())
        self.usable_edges = usable.number_of_nodes()
        largest = max(nx.strongly_connected_components(usable), key=len)
        self.graph: nx.DiGraph = usable.subgraph(largest).copy()

    def length(self, edge_id: str) -> float:
        return float(self.graph.nodes[edge_id]["length"])

    def free_flow_time(self, edge_id: str) -> float:
        node = self.graph.nodes[edge_id]
        return float(node["length"] / node["speed"])

    def edge_costs(
        self, *, kind: str, times: Mapping[str, float] | None = None
    ) -> dict[str, float]:
        """Cost of every edge: lengths, or travel times (free flow unless given)."""
        if kind == "length":
            return {e: self.length(e) for e in self.graph}
        costs = {e: self.free_flow_time(e) for e in self.graph}
        costs.update(times or {})
        return costs

    def weighted(self, costs: Mapping[str, float]) -> nx.DiGraph:
        """The graph with arc ``x -> y`` weighing ``costs[x]`` (start of x to start of y)."""
        g = nx.DiGraph()
        g.add_weighted_edges_from((x, y, costs[x]) for x, y in self.graph.edges)
        return g

    def start_costs(
        self, target: tuple[str, float], costs: Mapping[str, float], weighted: nx.DiGraph
    ) -> dict[str, float]:
        """Cost from the start of every edge to the target position ``(edge id, offset)``."""
        t, s_t = target
        weighted.add_edge(t, TARGET, weight=s_t * costs[t] / self.length(t))
        try:
            return dict(nx.single_source_dijkstra_path_length(weighted.reverse(copy=False), TARGET))
        finally:
            weighted.remove_node(TARGET)

    def vehicle_cost(
        self,
        vehicle: tuple[str, float],
        target: tuple[str, float],
        costs: Mapping[str, float],
        start_costs: Mapping[str, float],
    ) -> float:
        """Cost from a vehicle position to the target, given ``start_costs`` of that target."""
        e, s = vehicle
        t, s_t = target
        if e == t and s <= s_t:
            return (s_t - s) * costs[t] / self.length(t)
        rest = (self.length(e) - s) * costs[e] / self.length(e)
        return rest + min(
            (start_costs.get(y, np.inf) for y in self.graph.successors(e)), default=np.inf
        )

    def path_cost(
        self, source: tuple[str, float], target: tuple[str, float], costs: Mapping[str, float]
    ) -> float:
        """Cost from ``source`` to ``target`` (one networkx Dijkstra)."""
        start = self.start_costs(target, costs, self.weighted(costs))
        return self.vehicle_cost(source, target, costs, start)
