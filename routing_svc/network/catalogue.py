"""Road networks by name: small generated ones and the real ones eclipse-sumo ships.

Generated networks are made on demand with SUMO's ``netgenerate`` (and, for
``oneway``, ``netconvert``) from fixed recipes and fixed seeds, into a cache
directory (``$ROUTING_SVC_CACHE/nets``, else ``~/.cache/routing_svc/nets``).
The same SUMO version gives the same bytes every time: the only varying parts
of SUMO's output, the timestamp of the header comment and the output file
name, are normalised. A cached file is never overwritten unless asked, so a
network a fleet was built on does not change under it.

The real networks are the ``*.net.xml[.gz]`` files under
``<SUMO_HOME>/tools/game`` of the installed eclipse-sumo package, found at run
time and named after their folder (``tools/game/DRT/osm.net.xml`` is ``drt``);
they are never copied.

``routing-svc nets`` lists them all (:func:`add_parser`, :func:`run`).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from routing_svc.errors import InvalidInput, InvalidNetwork, UnknownNetwork
from routing_svc.network.sumo_tools import sumo_home, sumo_tool
from routing_svc.paths import cache_root

__all__ = [
    "GENERATED",
    "NetInfo",
    "Recipe",
    "add_parser",
    "cache_dir",
    "generate_network",
    "list_networks",
    "resolve_network",
    "run",
]

Source = Literal["generated", "eclipse-sumo"]
_HEADER_STAMP = re.compile(rb"<!-- generated on \S+ by ")


@dataclass(frozen=True, slots=True)
class NetInfo:
    """A network known by name.

    Attributes
    ----------
    name
        What :func:`resolve_network` accepts, e.g. ``"grid"`` or ``"drt"``.
    path
        Where the file is (for a generated network: where it will be).
    source
        ``"generated"`` (made by :func:`generate_network`) or ``"eclipse-sumo"``
        (shipped with the installed SUMO).
    exists
        Whether the file is there now.
    description
        One line saying what the network is.
    """

    name: str
    path: Path
    source: Source
    exists: bool
    description: str = ""


@dataclass(frozen=True, slots=True)
class Recipe:
    """How to make one generated network.

    ``netgenerate`` runs with ``args``; ``post``, if given, receives the
    generated file and the path to write the final network to.
    """

    name: str
    description: str
    args: tuple[str, ...]
    post: Callable[[Path, Path], None] | None = field(default=None, kw_only=True)


_ONEWAY_BLOCKS = 8
_ONEWAY_LENGTH = 150.0


def _one_way_interior(source: Path, target: Path) -> None:
    """Keep the outer ring two-way; make interior streets alternating one-ways.

    Interior row ``r`` runs east when ``r`` is odd and west when even; interior
    column ``c`` runs north when odd and south when even (a Manhattan pattern).
    Every junction stays strongly connected through the two-way ring.
    """
    import sumolib

    net = sumolib.net.readNet(str(source))
    last = _ONEWAY_BLOCKS - 1
    drop = []
    for edge in net.getEdges(withInternal=False):
        (x0, y0), (x1, y1) = edge.getFromNode().getCoord(), edge.getToNode().getCoord()
        if abs(y1 - y0) < 1e-6:  # horizontal: row index from y
            line, forward = round(y0 / _ONEWAY_LENGTH), x1 > x0
        else:  # vertical: column index from x
            line, forward = round(x0 / _ONEWAY_LENGTH), y1 > y0
        if 0 < line < last and forward != (line % 2 == 1):
            drop.append(edge.getID())
    _run_tool(
        "netconvert",
        ["--sumo-net-file", source.name, "--remove-edges.explicit", ",".join(sorted(drop))],
        output=target,
    )


GENERATED: dict[str, Recipe] = {
    recipe.name: recipe
    for recipe in (
        Recipe(
            "grid",
            "6x6 junction grid, 200 m blocks, all streets two-way",
            ("--grid", "--grid.number", "6", "--grid.length", "200", "--seed", "1"),
        ),
        Recipe(
            "spider",
            "spider web: 8 arms, 5 rings 150 m apart, all streets two-way",
            (
                "--spider",
                "--spider.arm-number",
                "8",
                "--spider.circle-number",
                "5",
                "--spider.space-radius",
                "150",
                "--seed",
                "1",
            ),
        ),
        Recipe(
            "oneway",
            "8x8 grid, 150 m blocks: two-way outer ring, alternating one-way interior "
            "streets (84 of 140 edges have no reverse)",
            (
                "--grid",
                "--grid.number",
                str(_ONEWAY_BLOCKS),
                "--grid.length",
                str(_ONEWAY_LENGTH),
                "--seed",
                "1",
            ),
            post=_one_way_interior,
        ),
    )
}
"""The recipes of the generated networks, by name."""


def cache_dir() -> Path:
    """Where generated networks go: ``$ROUTING_SVC_CACHE/nets`` or ``~/.cache/routing_svc/nets``."""
    return cache_root() / "nets"


def _run_tool(tool: str, args: list[str], *, output: Path) -> None:
    """Run a SUMO tool in ``output``'s folder, writing ``output`` (relative name)."""
    binary, env = sumo_tool(tool)
    command = [binary, *args, "--output-file", output.name]
    done = subprocess.run(command, cwd=output.parent, env=env, capture_output=True, text=True)
    if done.returncode != 0 or not output.is_file():
        raise InvalidNetwork(f"{tool} failed ({done.returncode}): {done.stderr.strip()[-2000:]}")


def _normalise(path: Path) -> bytes:
    """The file's bytes without the timestamp SUMO writes into its header comment."""
    return _HEADER_STAMP.sub(b"<!-- generated by ", path.read_bytes(), count=1)


def generate_network(name: str, *, out_dir: Path | None = None, force: bool = False) -> Path:
    """Return the path of generated network ``name``, making it if it is missing.

    Parameters
    ----------
    name
        A key of :data:`GENERATED`.
    out_dir
        Folder for the file; default :func:`cache_dir`.
    force
        Make the file again even if it exists.

    Raises
    ------
    UnknownNetwork
        For a name without a recipe.
    InvalidNetwork
        If a SUMO tool fails.
    """
    recipe = GENERATED.get(name)
    if recipe is None:
        raise UnknownNetwork(f"no generated network {name!r}; known: {', '.join(GENERATED)}")
    folder = out_dir if out_dir is not None else cache_dir()
    target = folder / f"{name}.net.xml"
    if target.is_file() and not force:
        return target
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder, prefix=f".{name}-") as scratch:
        work = Path(scratch)
        raw = work / f"{name}.raw.net.xml"
        _run_tool("netgenerate", list(recipe.args), output=raw)
        final = raw
        if recipe.post is not None:
            final = work / f"{name}.net.xml"
            recipe.post(raw, final)
        ready = work / "ready.net.xml"
        ready.write_bytes(_normalise(final))
        os.replace(ready, target)  # atomic: readers never see half a file
    return target


def _shipped() -> list[NetInfo]:
    """The real networks under ``<SUMO_HOME>/tools/game``, named by folder."""
    home = sumo_home()
    if home is None:
        return []
    game = home / "tools" / "game"
    files = sorted({*game.glob("**/*.net.xml"), *game.glob("**/*.net.xml.gz")})
    per_folder: dict[Path, int] = {}
    for path in files:
        per_folder[path.parent] = per_folder.get(path.parent, 0) + 1
    found = []
    for path in files:
        name = path.parent.name.lower()
        if per_folder[path.parent] > 1:
            name += "-" + path.name.split(".")[0].lower()
        where = path.relative_to(home).as_posix()
        found.append(NetInfo(name, path, "eclipse-sumo", True, f"SUMO's {where}"))
    return found


def list_networks(*, out_dir: Path | None = None) -> list[NetInfo]:
    """Every network known by name: the generated ones first, then SUMO's.

    Parameters
    ----------
    out_dir
        Folder of the generated networks; default :func:`cache_dir`.
    """
    folder = out_dir if out_dir is not None else cache_dir()
    paths = {name: folder / f"{name}.net.xml" for name in GENERATED}
    generated = [
        NetInfo(r.name, paths[r.name], "generated", paths[r.name].is_file(), r.description)
        for r in GENERATED.values()
    ]
    shipped = [net for net in _shipped() if net.name not in GENERATED]
    return generated + shipped


def named_network(text: str) -> tuple[str, str]:
    """``NAME=PATH`` as ``(name, path)``; a bare ``NAME`` is its own path
    (a catalogue name or a file, for :func:`resolve_network`).

    Raises
    ------
    InvalidInput
        An empty name or path.
    """
    name, sep, path = text.partition("=")
    if not sep:
        name = path = text
    if not name or not path:
        raise InvalidInput(f"a network is NAME=PATH or NAME, got {text!r}")
    return name, path


def resolve_network(name_or_path: str | os.PathLike[str], *, out_dir: Path | None = None) -> Path:
    """Turn a network name or a file path into the path of a network file.

    A generated network's name is generated if needed; a shipped network's
    name gives its file; any other argument must be an existing file.

    Raises
    ------
    UnknownNetwork
        Neither a known name nor an existing file.
    """
    text = os.fspath(name_or_path)
    if text in GENERATED:
        return generate_network(text, out_dir=out_dir)
    for net in _shipped():
        if net.name == text:
            return net.path
    path = Path(text)
    if path.is_file():
        return path
    known = ", ".join(net.name for net in list_networks(out_dir=out_dir))
    raise UnknownNetwork(f"{text!r} is neither a known network ({known}) nor a file")


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``nets`` command (``routing-svc nets [--json] [--generate]``)."""
    parser = subparsers.add_parser("nets", help="list the road networks known by name")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument(
        "--generate", action="store_true", help="generate the missing generated networks first"
    )
    parser.add_argument("--cache-dir", type=Path, default=None, help="folder of generated nets")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Print the known networks; return the exit status."""
    out_dir: Path | None = args.cache_dir
    if args.generate:
        for name in GENERATED:
            generate_network(name, out_dir=out_dir)
    nets = list_networks(out_dir=out_dir)
    if args.json:
        rows = [
            {
                "name": n.name,
                "path": str(n.path),
                "source": n.source,
                "exists": n.exists,
                "description": n.description,
            }
            for n in nets
        ]
        print(json.dumps(rows, indent=2))
        return 0
    from rich.console import Console
    from rich.table import Table

    table = Table(title="road networks")
    for column in ("name", "source", "exists"):
        table.add_column(column, no_wrap=True)
    table.add_column("description")
    table.add_column("path", overflow="fold")
    for n in nets:
        table.add_row(n.name, n.source, "yes" if n.exists else "no", n.description, str(n.path))
    Console().print(table)
    return 0
