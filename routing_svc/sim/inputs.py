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
    "write_stands_rerouter",
    "write_taxi_stands",
]

#: SUMO vType id of the fleet's vehicles.
FLEET_TYPE = "fleet"

#: Id of the rerouter that lists the taxi stands (SUMO idle algorithm ``taxistand``).
STANDS_REROUTER = "taxi_stands"

#: Length (m) of a taxi stand's parking area along its lane.
STAND_LENGTH = 20.0


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
    """A fleet vehicle and where it is inserted (its first reference position);
    ``area``: the SUMO parkingArea it starts parked in, if any."""

    id: str
    edge: str
    offset: float
    area: str | None = None


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
    stands: bool = False,
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
    stands : bool
        Whether idle taxis use the stands of :func:`write_taxi_stands` (SUMO's
        ``taxistand`` idle algorithm), choosing the closest one; vehicle ``k``
        starts parked at stand ``k`` (SUMO cannot send a taxi inserted on a
        stand to that stand).

    A vehicle with an ``area`` starts parked in that parkingArea instead
    (inserted at the start of its edge).
    """
    lines = [
        "<routes>",
        f'    <vType id="{FLEET_TYPE}" vClass="passenger" color="0,160,255">',
        '        <param key="has.taxi.device" value="true"/>',
    ]
    if stands:
        lines += [
            f'        <param key="device.taxi.stands-rerouter" value="{STANDS_REROUTER}"/>',
            '        <param key="parking.ignoreDest" value="1"/>',
        ]
    lines.append("    </vType>")
    for number, v in enumerate(vehicles):
        pos = _stop_offset(v.offset, lengths[v.edge])
        edge = quoteattr(v.edge)
        if v.area is not None:
            depart = 0.0
        elif stands:
            depart = _stand_span(v.offset, lengths[v.edge])[0]
        else:
            depart = max(pos - 1.0, 0.0)
        lines.append(
            f'    <vehicle id={quoteattr(v.id)} type="{FLEET_TYPE}" depart="0" '
            f'departPos="{depart:.2f}" line="taxi">'
        )
        lines.append(f"        <route edges={edge}/>")
        if stands or (park and v.area is not None):
            area = quoteattr(v.area if v.area is not None else _stand_id(number))
            lines.append(f'        <stop parkingArea={area} duration="{PARK_SECONDS:g}"/>')
        elif park:
            lines.append(
                f'        <stop edge={edge} endPos="{pos:.2f}" duration="{PARK_SECONDS:g}" '
                'parking="true"/>'
            )
        lines.append("    </vehicle>")
    lines.append("</routes>")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def passenger_lanes(net: Path, edges: Sequence[str]) -> dict[str, int]:
    """The rightmost lane index of each edge that passenger cars may use (0 if none says)."""
    import gzip

    from defusedxml import ElementTree

    wanted = set(edges)
    found: dict[str, int] = {}
    opener = gzip.open if net.name.endswith(".gz") else open
    with opener(net, "rb") as stream:
        for _, element in ElementTree.iterparse(stream, events=("end",)):
            if element.tag != "edge":
                continue
            edge = element.get("id", "")
            if edge in wanted:
                found[edge] = 0
                for lane in sorted(element.iter("lane"), key=lambda x: int(x.get("index", "0"))):
                    allow = lane.get("allow")
                    disallow = (lane.get("disallow") or "").split()
                    if (allow is None or "passenger" in allow.split()) and (
                        "passenger" not in disallow
                    ):
                        found[edge] = int(lane.get("index", "0"))
                        break
            element.clear()
    return found


def _stand_id(number: int) -> str:
    return f"stand{number:03d}"


def _stand_span(offset: float, length: float) -> tuple[float, float]:
    """Where a stand around ``offset`` begins and ends on a lane of ``length`` metres."""
    start = min(max(offset - STAND_LENGTH / 2.0, 0.0), max(length - STAND_LENGTH, 0.0))
    return start, min(start + STAND_LENGTH, length)


def write_taxi_stands(
    path: Path,
    sites: Sequence[FleetVehicle],
    *,
    lengths: dict[str, float],
    lanes: dict[str, int],
    capacity: int,
) -> Path:
    """Taxi stands for SUMO's ``taxistand`` idle algorithm, one per site.

    Each stand is a ``parkingArea`` of :data:`STAND_LENGTH` metres around the
    site on the edge's passenger lane, with room for ``capacity`` taxis; the
    rerouter :data:`STANDS_REROUTER` lists them (SUMO's taxi device reads the
    stands from it; with ``parking.ignoreDest`` an idle taxi picks the
    closest).
    """
    lines = ["<additional>"]
    stand_ids = []
    for number, site in enumerate(sites):
        start, end = _stand_span(site.offset, lengths[site.edge])
        stand = _stand_id(number)
        stand_ids.append(stand)
        lane = quoteattr(f"{site.edge}_{lanes.get(site.edge, 0)}")
        lines.append(
            f'    <parkingArea id="{stand}" lane={lane} startPos="{start:.2f}" '
            f'endPos="{end:.2f}" roadsideCapacity="{capacity}" friendlyPos="true"/>'
        )
    lines += _rerouter(stand_ids, [s.edge for s in sites])
    lines.append("</additional>")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _rerouter(areas: Sequence[str], edges: Sequence[str]) -> list[str]:
    """The rerouter :data:`STANDS_REROUTER` on ``edges``, listing the parkingAreas ``areas``."""
    on = quoteattr(" ".join(dict.fromkeys(edges)))
    lines = [f'    <rerouter id="{STANDS_REROUTER}" edges={on}>']
    lines.append('        <interval begin="0" end="1e9">')
    lines += [f"            <parkingAreaReroute id={quoteattr(a)}/>" for a in areas]
    lines += ["        </interval>", "    </rerouter>"]
    return lines


def write_stands_rerouter(path: Path, areas: Sequence[str], edges: Sequence[str]) -> Path:
    """The taxi stands of SUMO's ``taxistand`` idle algorithm: the rerouter
    :data:`STANDS_REROUTER` listing parkingAreas defined in another additional file
    (loaded before this one), on their ``edges``."""
    lines = ["<additional>", *_rerouter(areas, edges), "</additional>"]
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
    additional: Sequence[Path] = (),
    stops: Path | None = None,
) -> list[str]:
    """SUMO's command line (without the binary) for one co-simulation run.

    Parameters
    ----------
    dispatch : {"traci", "greedy", "greedyClosest"}
        ``traci``: the co-simulation dispatches; otherwise SUMO's taxi device
        does, every second, with that algorithm.
    idle : {"stop", "randomCircling", "taxistand"}
        What SUMO's taxi device does with an idle taxi.
    additional : sequence of Path
        SUMO additional files (e.g. the taxi stands).
    stops : Path, optional
        SUMO's stop output (every stop, with its parkingArea; unfinished ones too).
    """
    extra = ["--additional-files", ",".join(str(a) for a in additional)] if additional else []
    if stops is not None:
        extra += ["--stop-output", str(stops), "--stop-output.write-unfinished"]
    return [
        *extra,
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
