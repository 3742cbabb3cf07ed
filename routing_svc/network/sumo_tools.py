"""The SUMO installation the project runs: its home, and its command-line tools.

SUMO comes from the ``eclipse-sumo`` wheel (``sumo.SUMO_HOME``); without it, from
``$SUMO_HOME``. Tools run with ``SUMO_HOME`` set and, where the wheel ships PROJ's
data, ``PROJ_DATA``/``PROJ_LIB`` pointing at it (netconvert's geo-projection).
"""

from __future__ import annotations

import os
from pathlib import Path

from routing_svc.errors import InvalidNetwork

__all__ = ["sumo_home", "sumo_tool"]


def sumo_home() -> Path | None:
    """The installed SUMO's home: the eclipse-sumo package, else ``$SUMO_HOME``."""
    try:
        import sumo
    except ImportError:
        env = os.environ.get("SUMO_HOME")
        return Path(env) if env else None
    return Path(sumo.SUMO_HOME)


def sumo_tool(name: str) -> tuple[str, dict[str, str]]:
    """The command of SUMO's tool ``name`` (``netconvert``, ``netgenerate``, ...) and the
    environment to run it in.

    Raises
    ------
    InvalidNetwork
        SUMO, or this tool, is not installed.
    """
    home = sumo_home()
    if home is None or not (home / "bin" / name).is_file():
        raise InvalidNetwork(f"SUMO's {name} is not installed (no eclipse-sumo, no $SUMO_HOME)")
    env = {**os.environ, "SUMO_HOME": str(home)}
    proj = home / "data" / "proj"
    if proj.is_dir():
        env.setdefault("PROJ_DATA", str(proj))
        env.setdefault("PROJ_LIB", str(proj))
    return str(home / "bin" / name), env
