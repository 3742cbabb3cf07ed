"""The package's import graph: no cycles, and imports only point down (DESIGN.md, section 2).

The graph is read from the source with ``ast``, so it counts every import: at
module level, inside functions, and under ``if TYPE_CHECKING:``. An import
``from routing_svc.a import b`` is an edge to the module ``routing_svc.a.b`` if
that is a module, else to the package ``routing_svc.a``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx

PACKAGE = Path(__file__).resolve().parents[1] / "routing_svc"

#: layer -> the layers it must not import (DESIGN.md: cli -> service/sim -> store ->
#: optimum/demand -> network -> sa -> errors/types).
FORBIDDEN: dict[str, set[str]] = {
    "sa": {"network", "optimum", "demand", "store", "service", "sim", "paper", "cli"},
    "network": {"optimum", "demand", "store", "service", "sim", "paper"},
    "demand": {"store", "service", "sim", "paper"},
    "optimum": {"store", "service", "sim", "paper"},
    "store": {"service", "sim"},
    "service": {"sim", "paper", "cli"},
}


def module_names(package: Path) -> dict[str, Path]:
    """Dotted module name -> source file, for every ``.py`` file under ``package``."""
    names = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        names[".".join(parts)] = path
    return names


def import_graph(package: Path) -> nx.DiGraph:
    """Edges ``importer -> imported`` between the modules of ``package`` (every import)."""
    modules = module_names(package)
    root = package.name

    def owner(name: str) -> str | None:
        """The innermost module of the package that ``name`` lies in."""
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph = nx.DiGraph()
    graph.add_nodes_from(modules)
    for module, path in modules.items():
        here = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str | None] = []
            if isinstance(node, ast.Import):
                targets = [owner(alias.name) for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parent = here.split(".")[: len(here.split(".")) - node.level + 1]
                    base = ".".join([*parent, base] if base else parent)
                if base == root or base.startswith(root + "."):
                    names = [f"{base}.{alias.name}" for alias in node.names]
                    targets = [name if name in modules else owner(base) for name in names]
            for target in targets:
                if target is not None and target != module:
                    graph.add_edge(module, target)
    return graph


def layer(module: str) -> str:
    """``routing_svc.service.runtime`` -> ``service``; ``routing_svc.cli`` -> ``cli``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def cycles(graph: nx.DiGraph) -> list[list[str]]:
    """The groups of modules that import each other (directly or around a loop)."""
    groups = nx.strongly_connected_components(graph)
    return sorted(sorted(group) for group in groups if len(group) > 1)


def test_no_module_imports_another_that_imports_it_back() -> None:
    assert cycles(import_graph(PACKAGE)) == []


def test_imports_point_down_the_layers() -> None:
    graph = import_graph(PACKAGE)
    upward = sorted(
        f"{a} -> {b}" for a, b in graph.edges if layer(b) in FORBIDDEN.get(layer(a), set())
    )
    assert upward == []


def test_the_graph_sees_local_relative_and_type_checking_imports(tmp_path: Path) -> None:
    package = tmp_path / "pkg"
    (package / "low").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "low" / "__init__.py").write_text("from pkg.low.base import Base\n")
    (package / "low" / "base.py").write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n"
        "    from pkg.top import Top\n"
        "class Base: ...\n"
    )
    (package / "low" / "extra.py").write_text("from . import base\nfrom .base import Base\n")
    (package / "top.py").write_text(
        "import os\n"
        "def make():\n"
        "    from pkg.low import Base\n"
        "    import pkg.low.extra\n"
        "    return Base\n"
        "class Top: ...\n"
    )
    graph = import_graph(package)
    assert set(graph.edges) == {
        ("pkg.low", "pkg.low.base"),
        ("pkg.low.base", "pkg.top"),
        ("pkg.low.extra", "pkg.low.base"),
        ("pkg.top", "pkg.low"),
        ("pkg.top", "pkg.low.extra"),
    }
    assert cycles(graph) == [["pkg.low", "pkg.low.base", "pkg.low.extra", "pkg.top"]]
    assert layer("pkg.low.extra") == "low" and layer("pkg") == ""
