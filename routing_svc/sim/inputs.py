"""SUMO input files of a co-simulation: background traffic, fleet, persons, options.

Background traffic comes from SUMO's own ``randomTrips.py`` (seeded, checked
with ``duarouter`` through ``--validate``), or from a scenario's route files.
The fleet is a set of taxis (``has.taxi.device``) of the passenger class,
inserted at their reference positions; the requests are persons that ask for a
taxi ride (``<ride ... lines="taxi"/>``), so SUMO's taxi device handles the
reservations and SUMO's ``personinfo`` output measures every wait.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

from routing_svc.network.sumo_tools import sumo_home
from routing_svc.sim.backend import PARK_SECONDS, SimulationError

__all__ = [
    "FLEET_TYPE",
    "FleetVehicle",
    "Request",
    "random_trips",
    "sumo_options",
    "write_fleet",
    "write_persons",
]

#: SUMO vType id of the fleet's vehicles.
FLEET_TYPE = "fleet"


@dataclass(frozen=True, slots=True)
class Request:
    """One service request: a person who asks for a taxi at ``(edge, offset)``.

    ``to_edge`` / ``to_offset`` is where the ride ends.
    """

    id: str
    time: float
    edge: str
    offset: float
    to_edge: str
    to_offset: float


@dataclass(frozen=True, slots=True)
class FleetVehicle:
    """A fleet vehicle and where it is inserted (its first reference position)."""

    id: str
    edge: str
    offset: float


def random_trips(
    net: Path,
    out: Path,
    *,
    seed: int,
    end: float,
    density: float,
    min_distance: float = 300.0,
) -> Path:
    """Background traffic from SUMO's ``randomTrips.py``, validated by ``duarouter``.

    Parameters
    ----------
    net : Path
        The SUMO network.
    out : Path
        The trips file to write.
    seed : int
        randomTrips' seed: the same seed gives the same trips.
    end : float
        Last departure time (s); departures start at 0.
    density : float
        randomTrips' ``--insertion-density``: new vehicles per hour and
        kilometre of road.
    min_distance : float
        Straight-line distance (m) a trip must at least cover.

    Returns
    -------
    Path
        ``out``.
    """
    home = sumo_home()
    if home is None:
        raise SimulationError("SUMO is not installed (no eclipse-sumo package, no $SUMO_HOME)")
    script = home / "tools" / "randomTrips.py"
    command = [
        sys.executable,
        str(script),
        "-n",
        str(net),
        "-o",
        str(out),
        "--begin",
        "0",
        "--end",
        f"{end:g}",
        "--insertion-density",
        f"{density:g}",
        "--seed",
        str(seed),
        "--vehicle-class",
        "passenger",
        "--validate",
        "--fringe-factor",
        "5",
        "--min-distance",
        f"{min_distance:g}",
        "--prefix",
        "bg",
        "--trip-attributes",
        'departLane="best" departSpeed="max"',
    ]
    env = {**os.environ, "SUMO_HOME": str(home)}
    done = subprocess.run(command, cwd=out.parent, env=env, capture_output=True, text=True)
    if done.returncode != 0 or not out.is_file():
        raise SimulationError(f"randomTrips failed ({done.returncode}): {done.stderr[-2000:]}")
    return out


def _stop_offset(offset: float, length: float) -> float:
    """A stop position SUMO accepts on a lane of ``length`` metres."""
    return min(max(offset, 0.5), length)


def write_fleet(
    path: Path,
    vehicles: Sequence[FleetVehicle],
    *,
    lengths: dict[str, float],
    park: bool,
) -> Path:
    """The fleet's vType and vehicles, inserted at ``t = 0`` at their positions.

    Parameters
    ----------
    path : Path
        The route file to write.
    vehicles : sequence of FleetVehicle
        Ids and insertion positions.
    lengths : dict
        Length (m) of each edge used, to keep stop positions on the lane.
    park : bool
        Whether each vehicle parks at its insertion position (the co-simulation
        dispatches it; SUMO's own idle algorithm is used otherwise).
    """
    lines = [
        "<routes>",
        f'    <vType id="{FLEET_TYPE}" vClass="passenger" color="0,160,255">',
        '        <param key="has.taxi.device" value="true"/>',
        "    </vType>",
    ]
    for v in vehicles:
        pos = _stop_offset(v.offset, lengths[v.edge])
        edge = quoteattr(v.edge)
        lines.append(
            f'    <vehicle id={quoteattr(v.id)} type="{FLEET_TYPE}" depart="0" '
            f'departPos="{max(pos - 1.0, 0.0):.2f}" line="taxi">'
        )
        lines.append(f"        <route edges={edge}/>")
        if park:
            lines.append(
                f'        <stop edge={edge} endPos="{pos:.2f}" duration="{PARK_SECONDS:g}" '
                'parking="true"/>'
            )
        lines.append("    </vehicle>")
    lines.append("</routes>")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def write_persons(path: Path, requests: Sequence[Request]) -> Path:
    """Each request as a person who appears at its position and asks for a taxi ride."""
    lines = ["<routes>"]
    for r in sorted(requests, key=lambda r: (r.time, r.id)):
        lines.append(
            f'    <person id={quoteattr(r.id)} depart="{r.time:.2f}" departPos="{r.offset:.2f}">'
        )
        lines.append(
            f"        <ride from={quoteattr(r.edge)} to={quoteattr(r.to_edge)} "
            f'arrivalPos="{r.to_offset:.2f}" lines="taxi"/>'
        )
        lines.append("    </person>")
    lines.append("</routes>")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def sumo_options(
    *,
    net: Path,
    routes: Sequence[Path],
    end: float,
    seed: int,
    tripinfo: Path,
    dispatch: str,
    idle: str = "stop",
) -> list[str]:
    """SUMO's command line (without the binary) for one co-simulation run.

    Parameters
    ----------
    dispatch : {"traci", "greedy"}
        ``traci``: the co-simulation dispatches; ``greedy``: SUMO's taxi device
        does, every second.
    idle : {"stop", "randomCircling"}
        What SUMO's taxi device does with an idle taxi.
    """
    return [
        "--net-file",
        str(net),
        "--route-files",
        ",".join(str(r) for r in routes),
        "--begin",
        "0",
        "--end",
        f"{end:g}",
        "--step-length",
        "1",
        "--seed",
        str(seed),
        "--tripinfo-output",
        str(tripinfo),
        "--tripinfo-output.write-unfinished",
        "--device.taxi.dispatch-algorithm",
        dispatch,
        "--device.taxi.dispatch-period",
        "1",
        "--device.taxi.idle-algorithm",
        idle,
        "--ignore-route-errors",
        "--time-to-teleport",
        "300",
        "--no-step-log",
        "--no-warnings",
        "--duration-log.disable",
    ]
