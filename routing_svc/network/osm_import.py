"""OpenStreetMap extract -> SUMO network, with SUMO's own importer.

:func:`import_osm` takes an ``.osm`` / ``.osm.xml`` file (plain or gzip) or
its bytes, screens it as hostile XML with the limits of
:mod:`routing_svc.network.safe_xml` (root element ``<osm>``, no DOCTYPE or
entity, bounded decompression: a gzip bomb costs at most ``max_bytes`` of
disk and one chunk of memory), runs ``netconvert`` of the installed
eclipse-sumo on the screened copy and writes a gzipped ``.net.xml.gz``.

The options are those SUMO recommends for OpenStreetMap imports and that
``osmWebWizard.py`` / ``osmBuild.py`` use (:data:`NETCONVERT_OPTIONS`), with
SUMO's typemaps ``osmNetconvert.typ.xml`` and ``osmNetconvertUrbanDe.typ.xml``
(urban speed defaults). All road classes are kept by default, so that the
network still carries the footways that persons in a co-simulation walk on;
``cars_only`` adds ``--keep-edges.by-vclass passenger``. The project's
compiler then keeps the largest strongly connected car component as for any
network; :class:`ImportSummary` reports it together with what netconvert
joined, removed and warned about.
"""

from __future__ import annotations

import gzip
import os
import re
import shutil
import subprocess
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from routing_svc.errors import InvalidInput, InvalidNetwork, PayloadTooLarge
from routing_svc.network.cache import load_network
from routing_svc.network.identity import network_sha256
from routing_svc.network.safe_xml import XmlScreen, plain_xml_chunks
from routing_svc.network.sumo_tools import sumo_tool

__all__ = [
    "DEFAULT_MAX_OSM_BYTES",
    "NETCONVERT_OPTIONS",
    "ImportSummary",
    "NetconvertLog",
    "import_osm",
    "looks_like_osm",
    "osm_to_net_bytes",
]

DEFAULT_MAX_OSM_BYTES = 512 * 1024 * 1024
"""Largest plain (decompressed) OpenStreetMap XML that the command line accepts."""

NETCONVERT_OPTIONS = (
    "--geometry.remove",
    "--ramps.guess",
    "--junctions.join",
    "--tls.guess-signals",
    "--tls.discard-simple",
    "--tls.join",
    "--tls.default-type",
    "actuated",
    "--edges.join",
    "--roundabouts.guess",
    "--remove-edges.isolated",
    "--output.street-names",
    "--output.original-names",
)
"""SUMO's recommended netconvert options for OpenStreetMap (as ``osmWebWizard.py``)."""

TYPEMAPS = ("osmNetconvert.typ.xml", "osmNetconvertUrbanDe.typ.xml")
"""SUMO's typemaps under ``<SUMO_HOME>/data/typemap`` used for the import."""

_AGGREGATED = re.compile(r"^Warning: (\d+) total messages of type: (.*)$")
_COUNTED = {
    "osm_nodes": re.compile(r"^\s*(\d+) nodes loaded"),
    "osm_edges": re.compile(r"^\s*(\d+) edges loaded"),
    "junction_clusters_joined": re.compile(r"^\s*Joined (\d+) junction cluster"),
    "geometry_nodes_removed": re.compile(r"^\s*(\d+) nodes removed"),
    "roundabouts_guessed": re.compile(r"^\s*Guessed (\d+) roundabout"),
}


@dataclass(frozen=True, slots=True)
class NetconvertLog:
    """What netconvert said: its counts and its warnings, by kind.

    Attributes
    ----------
    osm_nodes, osm_edges : int
        OSM nodes read and OSM ways that became edges (before joining).
    junction_clusters_joined, geometry_nodes_removed, roundabouts_guessed : int
        What ``--junctions.join``, ``--geometry.remove`` and ``--roundabouts.guess`` did.
    warnings : dict[str, int]
        Warning count by kind (netconvert's message pattern, ``%`` for the varying parts).
    """

    osm_nodes: int = 0
    osm_edges: int = 0
    junction_clusters_joined: int = 0
    geometry_nodes_removed: int = 0
    roundabouts_guessed: int = 0
    warnings: dict[str, int] = field(default_factory=dict)

    @classmethod
    def parse(cls, stdout: str, stderr: str) -> NetconvertLog:
        """Read netconvert's verbose output and its warnings (``--aggregate-warnings 0``)."""
        counts: dict[str, int] = {}
        for line in stdout.splitlines():
            for name, pattern in _COUNTED.items():
                found = pattern.match(line)
                if found and name not in counts:
                    counts[name] = int(found.group(1))
        warnings: dict[str, int] = {}
        for line in stderr.splitlines():
            found = _AGGREGATED.match(line)
            if found:
                warnings[found.group(2)] = warnings.get(found.group(2), 0) + int(found.group(1))
            elif line.startswith("Warning: "):
                kind = re.sub(r"'[^']*'|\d+(\.\d+)?", "%", line[len("Warning: ") :])
                warnings[kind] = warnings.get(kind, 0) + 1
        return cls(**counts, warnings=dict(sorted(warnings.items(), key=lambda kv: -kv[1])))

    @property
    def warning_count(self) -> int:
        """All warnings."""
        return sum(self.warnings.values())


@dataclass(frozen=True, slots=True)
class ImportSummary:
    """The imported network, counted the way the rest of the project sees it.

    Attributes
    ----------
    output : str
        The written ``.net.xml.gz``.
    sha256 : str
        Its identity (:func:`~routing_svc.network.identity.network_sha256`).
    junctions, edges : int
        Junctions and edges of the whole network (internal ones not counted).
    car_edges : int
        Edges open to ``passenger``.
    car_component_edges, car_component_junctions : int
        The largest strongly connected car component: what fleets use.
    car_edges_outside_component : int
        Car edges the component leaves out (dead ends, islands).
    orig_boundary : tuple of float
        ``(lon_min, lat_min, lon_max, lat_max)`` of the source data (``<location origBoundary>``).
    netconvert : NetconvertLog
        What netconvert joined, removed and warned about.
    """

    output: str
    sha256: str
    junctions: int
    edges: int
    car_edges: int
    car_component_edges: int
    car_component_junctions: int
    car_edges_outside_component: int
    orig_boundary: tuple[float, float, float, float]
    netconvert: NetconvertLog

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``warning_count`` included)."""
        out = asdict(self)
        out["netconvert"]["warning_count"] = self.netconvert.warning_count
        return out

    def lines(self) -> list[str]:
        """A short human-readable report."""
        log = self.netconvert
        top = list(log.warnings.items())[:5]
        return [
            f"wrote {self.output}",
            f"  junctions {self.junctions}, edges {self.edges}, open to cars {self.car_edges}",
            f"  largest strongly connected car component: {self.car_component_junctions} "
            f"junctions, {self.car_component_edges} edges "
            f"({self.car_edges_outside_component} car edges outside it)",
            f"  netconvert: {log.osm_nodes} OSM nodes, {log.osm_edges} OSM road edges read; "
            f"{log.geometry_nodes_removed} geometry nodes removed, "
            f"{log.junction_clusters_joined} junction clusters joined, "
            f"{log.roundabouts_guessed} roundabouts guessed",
            f"  netconvert warnings: {log.warning_count} of {len(log.warnings)} kinds"
            + "".join(f"\n    {n:>5}  {kind}" for kind, n in top),
        ]


def screen_osm(source: Path | bytes | bytearray, *, destination: Path, max_bytes: int) -> int:
    """Write the plain XML of an OpenStreetMap extract to ``destination`` once screened.

    Parameters
    ----------
    source : Path, bytes or bytearray
        ``.osm[.xml]`` or its gzip, or the content of either.
    destination : Path
        Where the plain XML goes (written chunk by chunk, as screened).
    max_bytes : int
        Largest plain XML accepted; decompression stops just past it.

    Returns
    -------
    int
        Bytes written.

    Raises
    ------
    InvalidNetwork
        Empty input, corrupt or truncated gzip, malformed or hostile XML, a
        root element other than ``<osm>`` (the limits name themselves with
        :class:`~routing_svc.errors.XmlLimitExceeded`).
    PayloadTooLarge
        More than ``max_bytes`` of plain XML.
    """
    if max_bytes <= 0:
        raise InvalidInput(f"max_bytes must be positive, got {max_bytes}")
    if isinstance(source, Path) and not source.is_file():
        raise InvalidInput(f"no OpenStreetMap file at {source}")
    screen = XmlScreen(root="osm")
    written = 0
    try:
        with destination.open("wb") as out:
            for piece in plain_xml_chunks(source):
                written += len(piece)
                if written > max_bytes:
                    raise PayloadTooLarge(f"OpenStreetMap XML larger than {max_bytes} bytes")
                screen.feed(piece)
                out.write(piece)
        if written == 0:
            raise InvalidNetwork("the file is empty")
        screen.close()
    except InvalidNetwork as exc:
        if type(exc) is not InvalidNetwork:
            raise  # a named XML limit keeps its own title and members
        raise InvalidNetwork(f"not a usable OpenStreetMap extract: {exc.detail}") from None
    return written


def looks_like_osm(data: bytes | bytearray) -> bool:
    """Whether the root element of ``data`` (plain or gzip XML) is ``<osm>``.

    A sniff of the first inflated chunk through the same :class:`XmlScreen`,
    for telling an OpenStreetMap upload from a SUMO network; anything the
    screen refuses in that chunk is not taken for OpenStreetMap (the network
    checks then say what is wrong).
    """
    screen = XmlScreen(root="osm")
    try:
        first = next(iter(plain_xml_chunks(data)), b"")
        screen.feed(first)
    except InvalidNetwork:
        return False
    return screen.callbacks.root == "osm"


def run_netconvert(osm: Path, output: Path, *, cars_only: bool = False) -> NetconvertLog:
    """Convert the screened ``osm`` file into ``output`` (``.net.xml.gz``), both in one folder.

    netconvert runs in that folder with relative file names (SUMO's typemaps copied
    into it), so that the configuration it writes into the network's header names no
    temporary or install path.

    Raises
    ------
    InvalidNetwork
        If netconvert fails or writes no network.
    """
    if osm.parent != output.parent:
        raise InvalidInput("netconvert's input and output must share one folder")
    binary, env = sumo_tool("netconvert")
    home = Path(env["SUMO_HOME"])
    for typemap in TYPEMAPS:  # by name in the folder: the header names no install path
        shutil.copyfile(home / "data" / "typemap" / typemap, osm.parent / typemap)
    command = [
        binary,
        "--osm-files",
        osm.name,
        "--type-files",
        ",".join(TYPEMAPS),
        *NETCONVERT_OPTIONS,
        *(("--keep-edges.by-vclass", "passenger") if cars_only else ()),
        "--aggregate-warnings",
        "0",
        "--verbose",
        "--output-file",
        output.name,
    ]
    done = subprocess.run(
        command, cwd=osm.parent, env=env, capture_output=True, text=True, check=False
    )
    if done.returncode != 0 or not output.is_file():
        errors = [ln for ln in done.stderr.splitlines() if ln.startswith("Error")]
        detail = "; ".join(errors[-3:]) or done.stderr.strip()[-500:]
        raise InvalidNetwork(f"netconvert could not build a network from the extract: {detail}")
    return NetconvertLog.parse(done.stdout, done.stderr)


def import_osm(
    source: Path | bytes | bytearray,
    output: Path,
    *,
    max_bytes: int = DEFAULT_MAX_OSM_BYTES,
    cars_only: bool = False,
) -> ImportSummary:
    """Screen, convert and summarise an OpenStreetMap extract.

    Parameters
    ----------
    source : Path, bytes or bytearray
        The extract (plain or gzip), or its content.
    output : Path
        The ``.net.xml.gz`` to write; replaced atomically, never left half written.
    max_bytes : int
        Largest plain OpenStreetMap XML accepted.
    cars_only : bool
        Keep only edges open to ``passenger`` (default: every road class).

    Returns
    -------
    ImportSummary
        Counts of the written network and of what netconvert did.

    Raises
    ------
    InvalidInput
        An output name that does not end in ``.net.xml.gz``, a missing source.
    InvalidNetwork, PayloadTooLarge
        As :func:`screen_osm`; or netconvert failed, or made no car road.
    """
    if not output.name.endswith(".net.xml.gz"):
        raise InvalidInput(f"the output must be a gzipped network (*.net.xml.gz), got {output}")
    output.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=output.parent, prefix=".import-osm-") as scratch:
        work = Path(scratch)
        data, log = _convert(source, work, max_bytes=max_bytes, cars_only=cars_only)
        converted = work / "network.net.xml.gz"
        converted.write_bytes(data)
        junctions, edges, boundary = _count_network(converted)
        network = load_network(converted)
        os.replace(converted, output)
    reduction = network.reduction
    return ImportSummary(
        output=str(output),
        sha256=network_sha256(output),
        junctions=junctions,
        edges=edges,
        car_edges=reduction.usable_edges,
        car_component_edges=reduction.kept_edges,
        car_component_junctions=network.n_junctions,
        car_edges_outside_component=reduction.dropped_edges,
        orig_boundary=boundary,
        netconvert=log,
    )


def osm_to_net_bytes(data: bytes | bytearray, *, max_bytes: int) -> bytes:
    """Convert uploaded OpenStreetMap bytes into the gzip bytes of a SUMO network.

    The HTTP upload's path: the bytes :func:`import_osm` writes for the same extract;
    the result then goes through the network upload checks.
    """
    with tempfile.TemporaryDirectory(prefix="routing-svc-osm-") as scratch:
        return _convert(data, Path(scratch), max_bytes=max_bytes, cars_only=False)[0]


def _convert(
    source: Path | bytes | bytearray, work: Path, *, max_bytes: int, cars_only: bool
) -> tuple[bytes, NetconvertLog]:
    """Screen and convert an extract in the empty folder ``work``: the network's gzip
    bytes, the same for the same extract wherever and whenever it is converted (one
    network identity), and netconvert's log."""
    screened = work / "extract.osm.xml"
    screen_osm(source, destination=screened, max_bytes=max_bytes)
    converted = work / "converted.net.xml.gz"
    log = run_netconvert(screened, converted, cars_only=cars_only)
    with gzip.open(converted, "rb") as handle:
        plain = handle.read()
    plain = re.sub(rb"<!-- generated on \S+ by ", b"<!-- generated by ", plain, count=1)
    return gzip.compress(plain, mtime=0), log


def _count_network(path: Path) -> tuple[int, int, tuple[float, float, float, float]]:
    """Non-internal junctions and edges of a network netconvert wrote, and its origBoundary."""
    junctions = edges = 0
    boundary = (0.0, 0.0, 0.0, 0.0)
    with gzip.open(path, "rb") as handle:
        for _, element in ET.iterparse(handle):
            tag = element.tag
            if tag == "edge" and element.get("function") != "internal":
                edges += 1
            elif tag == "junction" and element.get("type") != "internal":
                junctions += 1
            elif tag == "location":
                values = [float(v) for v in element.get("origBoundary", "0,0,0,0").split(",")]
                boundary = (values[0], values[1], values[2], values[3])
            if tag in ("edge", "junction", "connection", "tlLogic", "roundabout"):
                element.clear()
    if edges == 0:
        raise InvalidNetwork("the extract holds no road that netconvert could use")
    return junctions, edges, boundary
