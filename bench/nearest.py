"""Benchmark: nearest-vehicle search of routing_svc against networkx and plain heapq.

Usage::

    python bench/nearest.py [--quick] [--badhersfeld PATH] [--cache-dir DIR]

Prints one JSON document to stdout. For each network (SUMO's DRT district,
Bad Hersfeld if present, a generated 160x160 grid) and each fleet size (10,
50, 200 vehicles) it reports the median microseconds per query of

- ``routing_svc``: ``RoadSpace.assign`` (one early-exit Dijkstra from the
  target on the reverse graph of end-state classes, i.e. the edges grouped
  by successor set, numba-compiled), end to end;
- ``heapq``: the same early-exit algorithm in plain Python with ``heapq``, on
  the reverse edge graph (no classes);
- ``networkx``: a full (cutoff-free) ``single_source_dijkstra`` from the
  target on the reverse edge graph, then the cheapest vehicle; networkx has
  no multi-vehicle early exit, so this is how it answers "which vehicle is
  nearest",

all measured in the same run on the same targets (the searches take turns
on blocks of 20 targets, so load changes on a shared machine hit them alike),
and the ratios ``speedup_vs_networkx`` and ``speedup_vs_heapq``. networkx runs
on a sample of the targets; its ratio compares both on that sample. Every
query's answer is checked to agree between the three. For every network it
reports the number of end-state classes, and for the grid the memory of the
compiled network (its arrays and end-state classes), of the search's work
arrays and of the arc records with the space's costs. ``--quick`` runs a small version (a 30x30
grid, fewer queries) for CI.
"""

from __future__ import annotations

import argparse
import heapq
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import networkx as nx
import numpy as np
import sumo
from bench_shared import SHARED

from routing_svc.network import CompiledNetwork, RoadSpace, default_cache_dir, load_network
from routing_svc.network.search import search_arcs
from routing_svc.sa.space import Requirement
from routing_svc.types import NetPosition

REPO = Path(__file__).resolve().parent.parent
SUMO_HOME = Path(sumo.SUMO_HOME)
DRT_NET = SUMO_HOME / "tools" / "game" / "DRT" / "osm.net.xml"
FLEETS = (10, 50, 200)
SEED = 2024
_BLOCK = 20
Answer = tuple[int, float]


def rss_bytes() -> int:
    """Current resident set size of this process."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def grid_net(folder: Path, size: int) -> Path:
    """A ``size`` x ``size`` junction grid with 100 m blocks, made once with netgenerate."""
    path = folder / f"grid{size}.net.xml"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=folder) as scratch:
            made = Path(scratch) / path.name
            subprocess.run(
                [
                    str(SUMO_HOME / "bin" / "netgenerate"),
                    "--grid",
                    f"--grid.number={size}",
                    "--grid.length=100",
                    "--output-file",
                    str(made),
                ],
                check=True,
                capture_output=True,
            )
            made.replace(path)
    return path


def compile_apart(path: Path, cache: Path) -> None:
    """Compile (if not cached) in a child process, so this process measures a cached load."""
    code = "import sys; from pathlib import Path; from routing_svc.network import load_network; "
    code += "load_network(sys.argv[1], cache_dir=Path(sys.argv[2]))"
    subprocess.run([sys.executable, "-c", code, str(path), str(cache)], check=True)


class HeapqSearch:
    """The early-exit reverse Dijkstra of routing_svc on the edge graph, in plain Python.

    One group, count 1, no end-state classes.
    """

    def __init__(self, space: RoadSpace) -> None:
        net = space.network
        self.indptr = net.rev_indptr.tolist()
        self.indices = net.rev_indices.tolist()
        self.length = net.length.tolist()
        self.cost = space.edge_costs.cost.tolist()
        self.rate = space.edge_costs.rate.tolist()

    def nearest(
        self, target: NetPosition, positions: list[NetPosition], speeds: list[float]
    ) -> Answer:
        on_edge: dict[int, list[int]] = {}
        for i, p in enumerate(positions):
            on_edge.setdefault(p.edge, []).append(i)
        t, s_t = target
        best: tuple[float, int, float] = (math.inf, -1, math.inf)
        for i in on_edge.get(t, ()):
            if positions[i].offset <= s_t:
                c = (s_t - positions[i].offset) * self.rate[t]
                best = min(best, (c / speeds[i], i, c))
        v_max = max(speeds)
        seed = s_t * self.rate[t]
        dist: dict[int, float] = {}
        heap: list[tuple[float, int]] = []
        for p in self.indices[self.indptr[t] : self.indptr[t + 1]]:
            if seed < dist.get(p, math.inf):
                dist[p] = seed
                heapq.heappush(heap, (seed, p))
        while heap:
            key, x = heapq.heappop(heap)
            if key > dist[x]:
                continue
            if best[0] < key / v_max:
                break
            for i in on_edge.get(x, ()):
                if x != t or positions[i].offset > s_t:
                    c = key + (self.length[x] - positions[i].offset) * self.rate[x]
                    best = min(best, (c / speeds[i], i, c))
            through = key + self.cost[x]
            for p in self.indices[self.indptr[x] : self.indptr[x + 1]]:
                if through < dist.get(p, math.inf):
                    dist[p] = through
                    heapq.heappush(heap, (through, p))
        return best[1], best[2]


class NetworkxSearch:
    """Full single-source Dijkstra from the target on the reverse edge graph (networkx)."""

    def __init__(self, space: RoadSpace) -> None:
        net = space.network
        self.space = space
        cost = space.edge_costs.cost
        heads = np.repeat(np.arange(net.n_edges), np.diff(net.rev_indptr))
        self.graph = nx.DiGraph()
        self.graph.add_weighted_edges_from(
            zip(heads.tolist(), net.rev_indices.tolist(), cost[heads].tolist(), strict=True)
        )

    def nearest(
        self, target: NetPosition, positions: list[NetPosition], speeds: list[float]
    ) -> Answer:
        net, rate = self.space.network, self.space.edge_costs.rate
        t, s_t = target
        seed = s_t * rate[t]
        source = "target"
        self.graph.add_weighted_edges_from(
            (source, int(p), seed)
            for p in net.rev_indices[net.rev_indptr[t] : net.rev_indptr[t + 1]]
        )
        try:
            dist = nx.single_source_dijkstra_path_length(self.graph, source)
        finally:
            self.graph.remove_node(source)
        best: tuple[float, int, float] = (math.inf, -1, math.inf)
        for i, (e, s) in enumerate(positions):
            if e == t and s <= s_t:
                c = (s_t - s) * rate[t]
            elif e in dist:
                c = dist[e] + (net.length[e] - s) * rate[e]
            else:
                continue
            best = min(best, (c / speeds[i], i, c))
        return best[1], best[2]


def interleaved_medians(
    searches: dict[str, Callable[[NetPosition], Answer]],
    targets: list[NetPosition],
) -> dict[str, tuple[float, list[Answer]]]:
    """Median microseconds per query of each search, and its answers.

    The searches take turns on blocks of targets (in rotating order), so a
    change in machine load during the run affects them all alike; within a
    block the targets differ, so no search profits from another's warm cache.
    """
    times: dict[str, list[int]] = {name: [] for name in searches}
    answers: dict[str, list[Answer]] = {name: [] for name in searches}
    names = list(searches)
    for block, lo in enumerate(range(0, len(targets), _BLOCK)):
        turn = block % len(names)
        for name in names[turn:] + names[:turn]:
            for target in targets[lo : lo + _BLOCK]:
                start = time.perf_counter_ns()
                answers[name].append(searches[name](target))
                times[name].append(time.perf_counter_ns() - start)
    return {name: (float(np.median(times[name])) / 1000.0, answers[name]) for name in names}


def agree(a: list[Answer], b: list[Answer]) -> bool:
    """Same vehicle (or the same cost, for exact ties) on every query."""
    return all(
        x[0] == y[0] or math.isclose(x[1], y[1], rel_tol=1e-9) for x, y in zip(a, b, strict=True)
    )


def bench_fleet(
    space: RoadSpace,
    reference: tuple[HeapqSearch, NetworkxSearch],
    n_vehicles: int,
    *,
    queries: int,
    nx_queries: int,
) -> dict[str, Any]:
    """Time the three searches for one fleet size on one network."""
    rng = np.random.default_rng(SEED + n_vehicles)
    net = space.network

    def positions(n: int) -> list[NetPosition]:
        edges = rng.integers(net.n_edges, size=n)
        return [NetPosition(int(e), float(rng.uniform(0.0, net.length[e]))) for e in edges]

    fleet, targets = positions(n_vehicles), positions(queries)
    speeds = np.ones(n_vehicles)
    speed_list = speeds.tolist()
    requirement = Requirement(np.zeros(n_vehicles, dtype=np.int64), np.ones(1, dtype=np.int64))

    def ours(target: NetPosition) -> Answer:
        result = space.assign(target, fleet, speeds, requirement)
        return result.mover, result.mover_cost

    heapq_search, nx_search = reference
    for target in targets[:20]:
        ours(target)
    nx_targets = targets[:: max(1, queries // nx_queries)][:nx_queries]
    measured = interleaved_medians(
        {
            "routing_svc": ours,
            "heapq": lambda t: heapq_search.nearest(t, fleet, speed_list),
        },
        targets,
    )
    measured |= interleaved_medians(
        {
            "routing_svc_nx_sample": ours,
            "networkx": lambda t: nx_search.nearest(t, fleet, speed_list),
        },
        nx_targets,
    )
    ours_us, ours_answers = measured["routing_svc"]
    heapq_us, heapq_answers = measured["heapq"]
    nx_us, nx_answers = measured["networkx"]
    sample_us, sample_answers = measured["routing_svc_nx_sample"]
    return {
        "vehicles": n_vehicles,
        "queries": queries,
        "networkx_queries": nx_queries,
        "routing_svc_us": round(ours_us, 2),
        "heapq_us": round(heapq_us, 2),
        "networkx_us": round(nx_us, 2),
        "speedup_vs_heapq": round(heapq_us / ours_us, 1),
        "routing_svc_us_on_networkx_targets": round(sample_us, 2),
        "speedup_vs_networkx": round(nx_us / sample_us, 1),
        "answers_agree": agree(ours_answers, heapq_answers) and agree(sample_answers, nx_answers),
    }


def bench_network(
    path: Path, cache: Path, *, queries: int, nx_queries: int, with_memory: bool
) -> dict[str, Any]:
    """Compile (apart), load from cache, and time every fleet size."""
    compile_apart(path, cache)
    before = rss_bytes()
    start = time.perf_counter()
    network: CompiledNetwork = load_network(path, cache_dir=cache)
    load_s = time.perf_counter() - start
    space = RoadSpace(network, either_way=False)
    memory = {
        "compiled_arrays_bytes": network.nbytes(),
        "search_buffers_bytes": space.search_buffer_bytes(),
        "search_arcs_bytes": search_arcs(network.end_classes, space.edge_costs).nbytes,
        "rss_delta_after_cached_load_bytes": rss_bytes() - before,
    }
    report: dict[str, Any] = {
        "file": str(path),
        "edges": network.n_edges,
        "connections": network.n_connections,
        "junctions": network.n_junctions,
        "end_state_classes": network.end_classes.n_classes,
        "class_arcs": int(network.end_classes.arc_edge.shape[0]),
        "usable_edges": network.reduction.usable_edges,
        "dropped_edges": network.reduction.dropped_edges,
        "cached_load_s": round(load_s, 3),
    }
    if with_memory:
        report["memory"] = memory
    reference = (HeapqSearch(space), NetworkxSearch(space))
    report["results"] = [
        bench_fleet(space, reference, n, queries=queries, nx_queries=nx_queries) for n in FLEETS
    ]
    return report


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="small version for CI")
    parser.add_argument(
        "--badhersfeld",
        type=Path,
        default=SHARED / "badhersfeld.net.xml.gz",
    )
    parser.add_argument(
        "--cache-dir", type=Path, default=None, help="compiled networks and the generated grid"
    )
    args = parser.parse_args(argv)
    cache = args.cache_dir if args.cache_dir is not None else default_cache_dir()
    grid_size = 30 if args.quick else 160
    queries, nx_queries = (100, 5) if args.quick else (2000, 20)
    grid_nx_queries = 3 if args.quick else 5
    networks: dict[str, Any] = {}
    networks["drt"] = bench_network(
        DRT_NET, cache, queries=queries, nx_queries=nx_queries, with_memory=False
    )
    if args.badhersfeld.is_file():
        networks["badhersfeld"] = bench_network(
            args.badhersfeld, cache, queries=queries, nx_queries=nx_queries, with_memory=False
        )
    else:
        networks["badhersfeld"] = {"skipped": f"no file at {args.badhersfeld}"}
    grid = grid_net(cache / "bench", grid_size)
    networks[f"grid{grid_size}"] = bench_network(
        grid, cache, queries=queries, nx_queries=grid_nx_queries, with_memory=True
    )
    headline = next(r for r in networks[f"grid{grid_size}"]["results"] if r["vehicles"] == 50)
    report = {
        "benchmark": "nearest-vehicle search: median microseconds per query",
        "quick": args.quick,
        "machine": {
            "cpus": os.cpu_count(),
            "load_average_1min": round(os.getloadavg()[0], 2),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "networkx": nx.__version__,
        },
        "networks": networks,
        "grid_50_vehicles": {
            "routing_svc_us": headline["routing_svc_us"],
            "target_us": 60.0,
            "speedup_vs_networkx": headline["speedup_vs_networkx"],
            "target_speedup_vs_networkx": 20.0,
        },
    }
    json.dump(report, sys.stdout, indent=2)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
