"""Traffic lights that never give a link green.

SUMO runs, for each traffic light, the last program (``tlLogic``) loaded for it.
A link of that light (a ``connection`` with ``tl`` and ``linkIndex``) whose state
is ``G`` or ``g`` in none of the program's phases stays red for the whole run:
the vehicles that need it stop at the line until SUMO teleports them
(``--time-to-teleport``), and routes, travel times and waits through that
junction stop meaning anything. Networks made for a player who switches the
lights by hand have such programs (``tools/game/bs3d``: phases of 1,000 s, most
links of its one light never green). ``netconvert --tls.rebuild`` gives a
network ordinary fixed-time programs.

Only links between edges of the compiled network (its vehicle class, its
largest strongly connected component) count: a pedestrian crossing or a rail
link that is always red stops no car.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import sumolib

from routing_svc.network.compile import CompiledNetwork

__all__ = ["SignalAudit", "audit_signals"]

#: Link states in which a vehicle may pass (SUMO's ``G``: priority, ``g``: yield).
GREEN = frozenset("Gg")

#: At most this many blocked links are named in :meth:`SignalAudit.to_dict`.
NAMED_LINKS = 5


@dataclass(frozen=True, slots=True)
class SignalAudit:
    """The traffic lights of a network as SUMO will run them.

    Attributes
    ----------
    signals : int
        Traffic lights with a program.
    links : int
        Their links between edges of the network (distinct ``(from, to)`` pairs).
    never_green : tuple[str, ...]
        Those links no phase of the running program lets pass, as
        ``"light: from -> to"``, sorted.
    longest_phase : float
        The longest phase of any running program (s); 0 without lights.
    """

    signals: int
    links: int
    never_green: tuple[str, ...]
    longest_phase: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, naming the first :data:`NAMED_LINKS` blocked links."""
        return {
            "signals": self.signals,
            "links": self.links,
            "never_green": len(self.never_green),
            "never_green_links": list(self.never_green[:NAMED_LINKS]),
            "longest_phase_s": self.longest_phase,
        }

    def warning(self, net: str) -> str | None:
        """A one-paragraph warning if a link is never green, else ``None``."""
        if not self.never_green:
            return None
        return (
            f"warning: {len(self.never_green)} of the {self.links} signalled links of {net} "
            f"never turn green in the programs SUMO runs (e.g. {self.never_green[0]}; the "
            f"longest phase lasts {self.longest_phase:g} s). Vehicles that need them wait at "
            "the line until SUMO teleports them. `netconvert -s NET --tls.rebuild -o OUT` "
            "gives the network ordinary fixed-time programs."
        )


def audit_signals(path: Path, network: CompiledNetwork) -> SignalAudit:
    """Find the links of ``network`` that the traffic lights of ``path`` never let pass.

    Parameters
    ----------
    path : Path
        The ``.net.xml[.gz]`` ``network`` was compiled from (already screened by
        :func:`~routing_svc.network.cache.load_network`).
    network : CompiledNetwork
        Its compiled form: which edges count.

    Returns
    -------
    SignalAudit
    """
    running: dict[str, list[str]] = {}
    longest: dict[str, float] = {}
    links: dict[str, set[tuple[int, str, str]]] = {}
    edges = network.edge_index
    for element in sumolib.xml.parse(str(path), ["tlLogic", "connection"]):
        if element.name == "tlLogic":
            phases = element.getChild("phase") or []
            running[element.id] = [str(p.state) for p in phases]  # the last program loaded
            longest[element.id] = max((float(p.duration) for p in phases), default=0.0)
        elif element.hasAttribute("tl") and element.hasAttribute("linkIndex"):
            origin, destination = str(element.attr_from), str(element.to)
            if origin in edges and destination in edges:
                links.setdefault(element.tl, set()).add(
                    (int(element.linkIndex), origin, destination)
                )
    blocked: set[tuple[str, str, str]] = set()
    passing: set[tuple[str, str]] = set()
    for light, controlled in links.items():
        states = running.get(light)
        if not states:
            continue
        for index, origin, destination in controlled:
            if any(index < len(s) and s[index] in GREEN for s in states):
                passing.add((origin, destination))
            else:
                blocked.add((light, origin, destination))
    counted = passing | {(origin, destination) for _, origin, destination in blocked}
    # a pair of edges with one lane-to-lane link that turns green is not blocked
    never = tuple(
        sorted(f"{light}: {o} -> {d}" for light, o, d in blocked if (o, d) not in passing)
    )
    return SignalAudit(
        signals=len(running),
        links=len(counted),
        never_green=never,
        longest_phase=max(longest.values(), default=0.0),
    )
