"""What the benchmarks share: the folder of the shared networks; for the learning
benchmarks, their networks, refusing an unknown network or demand before any work, the
medians over seeds and their worst case, and the report's last two keys (its records and
the seconds it took)."""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from routing_svc.demand.spec import parse_demand_spec
from routing_svc.errors import InvalidInput, UnknownNetwork
from routing_svc.network.catalogue import named_network, resolve_network

SHARED = Path(__file__).resolve().parents[2] / "shared" / "nets"
"""The shared networks beside the checkout."""

NETWORKS = {
    "drt": "drt",
    "bs3d": "bs3d",
    "badhersfeld": str(SHARED / "badhersfeld.net.xml.gz"),
    "bologna": str(SHARED / "bologna.net.xml.gz"),
    "grid": "grid",
    "spider": "spider",
    "oneway": "oneway",
}
"""The networks every learning benchmark runs on by default."""

Record = dict[str, Any]


def network_name(net: str) -> str:
    """The name a ``--nets`` entry is reported under (``NAME`` or ``NAME=FILE``)."""
    return named_network(net)[0]


def network_file(net: str) -> str:
    """The SUMO network of a ``--nets`` entry: a known name, or ``NAME=FILE``."""
    path = named_network(net)[1]
    return str(resolve_network(NETWORKS.get(path, path)))


def refuse_unknown(
    parser: argparse.ArgumentParser, nets: Iterable[str], demands: Iterable[str] = ()
) -> None:
    """Exit with 2 (``parser.error``) on a network the benchmarks cannot load (naming the
    ones they know) or a demand spec ``simulate --demand`` refuses."""
    try:
        for net in nets:
            network_file(net)
    except (InvalidInput, UnknownNetwork) as e:
        parser.error(f"{e}; the benchmarks' networks: {', '.join(NETWORKS)}, or NAME=FILE")
    try:
        for spec in demands:
            parse_demand_spec(spec)
    except InvalidInput as e:
        parser.error(str(e))


def medians_over_seeds(
    records: Sequence[Record], case: Callable[[Record], str], rules: Sequence[str]
) -> dict[str, dict[str, float]]:
    """Per case (``case(record)``), each rule's median of ``record["gaps"][rule]``."""
    cases: dict[str, list[Record]] = {}
    for r in records:
        cases.setdefault(case(r), []).append(r)
    return {
        key: {rule: statistics.median(r["gaps"][rule] for r in rs) for rule in rules}
        for key, rs in cases.items()
    }


def worst_and_mean_by_size(
    medians: dict[str, dict[str, float]], sizes: Iterable[int], rules: Sequence[str]
) -> dict[str, dict[str, dict[str, Any]]]:
    """Per size (the last part of a case's name), per rule: the worst case's median (with
    the case) and the mean of the medians."""
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for size in sorted(set(sizes)):
        rows = {k: v for k, v in medians.items() if k.endswith(f"/{size}")}
        out[str(size)] = {
            rule: {
                "worst": max((v[rule], k) for k, v in rows.items()),
                "mean_of_medians": statistics.fmean(v[rule] for v in rows.values()),
            }
            for rule in rules
        }
    return out


def finished(report: Record, records: Sequence[Record], started: float) -> Record:
    """``report`` with ``records`` and the seconds since ``started`` as its last keys."""
    return {**report, "records": list(records), "seconds": time.perf_counter() - started}
