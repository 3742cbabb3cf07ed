"""Benchmark: the XML screen on hostile uploads and on real networks.

Usage::

    python bench/hostile_xml.py [--quick] [--cache-dir DIR]

Prints one JSON document to stdout. Every case runs in a fresh child
process, which builds its input, resets its peak RSS (``/proc/self/clear_refs``),
screens the input and reports the seconds and the growth of ``VmHWM`` over
the RSS it had before:

- hostile uploads held in memory, as the service holds a request body, plain
  and gzip-compressed, through ``read_net_bytes`` with the service's 64 MiB
  limit: 40 MiB of ``<``, one 40 MiB attribute value, 40 MiB of text in one
  element, 2 million attributes on one element, a 40 MiB attribute name, a
  40 MiB comment, 40 MiB of ``<a/>``;
- real networks as files, through ``check_net_xml_file`` (the start-up path):
  SUMO's DRT and bs3d, Bad Hersfeld and bologna (``../shared/nets``) and a
  160 x 160 ``netgenerate`` grid (101,760 edges, generated once into the cache
  folder; ``--quick`` uses a 40 x 40 grid).

The baseline, measured in the same run, is ``badhersfeld_in_memory``: the
plain XML of Bad Hersfeld (22 MB, a real town) screened in memory like an
upload. Every case reports ``ratio_to_baseline`` (its seconds over the
baseline's) and ``seconds_per_mib``.
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import platform
import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import sumo
from bench_shared import SHARED

from routing_svc.errors import RoutingSvcError, XmlLimitExceeded
from routing_svc.network.safe_xml import check_net_xml_file, read_net_bytes

REPO = Path(__file__).resolve().parent.parent
SUMO_HOME = Path(sumo.SUMO_HOME)
MIB = 1 << 20
UPLOAD_LIMIT = 64 * MIB
BASELINE = "badhersfeld_in_memory"

HOSTILE: dict[str, Callable[[], bytes]] = {
    "junk_40MiB": lambda: b"<" * (40 * MIB),
    "attribute_value_40MiB": lambda: b'<net><edge id="' + b"a" * (40 * MIB) + b'"/></net>',
    "text_40MiB": lambda: b"<net><edge>" + b"t" * (40 * MIB) + b"</edge></net>",
    "attributes_2M": lambda: (
        b"<net><edge " + b" ".join(b'a%d="1"' % i for i in range(2_000_000)) + b"/></net>"
    ),
    "attribute_name_40MiB": lambda: b"<net><edge " + b"n" * (40 * MIB) + b'="1"/></net>',
    "comment_40MiB": lambda: b"<net><!--" + b"c" * (40 * MIB) + b"--></net>",
    "elements_40MiB": lambda: b"<net>" + b"<a/>" * (10 * MIB) + b"</net>",
}


def hwm_kib() -> int:
    """Peak resident set size of this process (``VmHWM``), KiB."""
    status = Path("/proc/self/status").read_text()
    found = re.search(r"VmHWM:\s+(\d+)", status)
    assert found is not None
    return int(found.group(1))


def reset_peak() -> None:
    """Let ``VmHWM`` start again from the current RSS."""
    Path("/proc/self/clear_refs").write_text("5")


def grid_net(folder: Path, size: int) -> Path:
    """A ``size`` x ``size`` junction grid with 100 m blocks, made once with netgenerate."""
    path = folder / f"grid{size}.net.xml"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        made = path.with_suffix(".tmp")
        subprocess.run(
            [str(SUMO_HOME / "bin" / "netgenerate"), "--grid", f"--grid.number={size}",
             "--grid.length=100", "--output-file", str(made)],
            check=True, capture_output=True,
        )  # fmt: skip
        made.replace(path)
    return path


def real_networks(cache: Path, *, quick: bool) -> dict[str, Path]:
    """The real networks, by case name."""
    nets = {
        "drt": SUMO_HOME / "tools" / "game" / "DRT" / "osm.net.xml",
        "bs3d": SUMO_HOME / "tools" / "game" / "bs3d" / "bs.net.xml",
        "badhersfeld": SHARED / "badhersfeld.net.xml.gz",
        "bologna": SHARED / "bologna.net.xml.gz",
    }
    size = 40 if quick else 160
    nets[f"grid{size}"] = grid_net(cache, size)
    return nets


def run_case(kind: str, name: str, arg: str) -> dict[str, Any]:
    """Screen one input in this process; its seconds, peak growth and outcome."""
    if kind == "file":
        path = Path(arg)
        size = (
            len(gzip.decompress(path.read_bytes())) if path.suffix == ".gz" else path.stat().st_size
        )

        def action() -> object:
            check_net_xml_file(path)
            return None
    else:
        data = gzip.decompress(Path(arg).read_bytes()) if name == BASELINE else HOSTILE[name]()
        if kind == "gzip":
            data = gzip.compress(data, compresslevel=6)
        size = len(data)

        def action() -> object:
            return read_net_bytes(data, max_bytes=UPLOAD_LIMIT)

    before = hwm_kib()
    reset_peak()
    start_rss = hwm_kib()
    t0 = time.perf_counter()
    try:
        action()
        outcome = "accepted"
    except XmlLimitExceeded as exc:
        outcome = f"rejected: {exc.limit}"
    except RoutingSvcError as exc:
        outcome = f"rejected: {type(exc).__name__}"
    seconds = time.perf_counter() - t0
    return {
        "input_mib": round(size / MIB, 2),
        "seconds": round(seconds, 4),
        "extra_peak_mib": round((hwm_kib() - start_rss) / 1024, 1),
        "rss_before_mib": round(min(before, start_rss) / 1024, 1),
        "outcome": outcome,
    }


def in_child(kind: str, name: str, arg: str = "") -> dict[str, Any]:
    """:func:`run_case` in a fresh Python process."""
    done = subprocess.run(
        [sys.executable, __file__, "--case", kind, name, arg],
        check=True, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    result: dict[str, Any] = json.loads(done.stdout)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="a 40 x 40 grid instead of 160 x 160")
    parser.add_argument("--cache-dir", type=Path, default=Path.home() / ".cache" / "routing_svc")
    parser.add_argument("--case", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        print(json.dumps(run_case(*args.case)))
        return
    baseline = in_child("memory", BASELINE, str(SHARED / "badhersfeld.net.xml.gz"))
    cases: dict[str, dict[str, Any]] = {}
    for name in HOSTILE:
        cases[name] = in_child("memory", name)
        cases[name + "_gzip"] = in_child("gzip", name)
    for name, path in real_networks(args.cache_dir / "bench", quick=args.quick).items():
        cases[name] = in_child("file", name, str(path))
    for case in (baseline, *cases.values()):
        case["ratio_to_baseline"] = round(case["seconds"] / baseline["seconds"], 3)
        case["seconds_per_mib"] = round(case["seconds"] / max(case["input_mib"], 1e-9), 4)
    report = {
        "benchmark": "hostile_xml",
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "baseline": {"name": BASELINE, **baseline},
        "cases": cases,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
