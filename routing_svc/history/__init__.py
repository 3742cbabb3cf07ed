"""Importing a history of calls (a CAD export) into a fleet, and its report.

::

    read_calls(path) -> CallTable                         calls.py
    place_locally / place_remotely -> PlacedCalls         places.py
    replay_history(table, placed, client, fleet)          replay.py
    history_fleet_spec(...)  (start at the p-median)      creation.py
    write_report(folder, ...)                             report.py
    routing-svc history import | create-fleet             command.py
"""

from routing_svc.history.calls import BadRow, CallTable, read_calls
from routing_svc.history.creation import history_fleet_spec
from routing_svc.history.places import PlacedCalls, place_locally, place_remotely
from routing_svc.history.replay import (
    HistoryInterrupted,
    HistoryRefused,
    HttpHistoryClient,
    ImportResult,
    InProcessHistoryClient,
    replay_history,
)

__all__ = [
    "BadRow",
    "CallTable",
    "HistoryInterrupted",
    "HistoryRefused",
    "HttpHistoryClient",
    "ImportResult",
    "InProcessHistoryClient",
    "PlacedCalls",
    "history_fleet_spec",
    "place_locally",
    "place_remotely",
    "read_calls",
    "replay_history",
]
