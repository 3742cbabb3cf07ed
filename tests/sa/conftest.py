"""Shared helpers of the SA tests."""

from __future__ import annotations

from collections.abc import Iterable, Mapping


def hand_made_net_xml(
    junctions: Mapping[str, tuple[float, float]],
    edges: Mapping[str, tuple[str, str, float]],
    turns: Iterable[tuple[str, str]],
) -> str:
    """A SUMO ``.net.xml`` of one-lane edges (``id: (from, to, length)``) joined by ``turns``."""
    bounds = [min(x for x, _ in junctions.values()), min(y for _, y in junctions.values())]
    bounds += [max(x for x, _ in junctions.values()), max(y for _, y in junctions.values())]
    box = ",".join(f"{v:g}" for v in bounds)
    parts = [
        f'<net version="1.9"><location netOffset="0,0" convBoundary="{box}" '
        f'origBoundary="{box}" projParameter="!"/>'
    ]
    for edge, (start, end, length) in edges.items():
        (x0, y0), (x1, y1) = junctions[start], junctions[end]
        parts.append(
            f'<edge id="{edge}" from="{start}" to="{end}"><lane id="{edge}_0" index="0" '
            f'speed="10" length="{length}" shape="{x0},{y0} {x1},{y1}"/></edge>'
        )
    for junction, (x, y) in junctions.items():
        incoming = " ".join(f"{e}_0" for e, (_, end, _) in edges.items() if end == junction)
        parts.append(
            f'<junction id="{junction}" type="priority" x="{x}" y="{y}" '
            f'incLanes="{incoming}" intLanes="" shape="{x},{y}"/>'
        )
    for src, dst in turns:
        parts.append(
            f'<connection from="{src}" to="{dst}" fromLane="0" toLane="0" dir="s" state="M"/>'
        )
    return "".join(parts) + "</net>"
