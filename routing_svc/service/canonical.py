"""Canonical JSON of events, and the result of a target event written from a template.

Every event's payload and result are stored as canonical JSON (:func:`dumps`:
sorted keys, no spaces, ASCII, floats that round-trip exactly), which replay
compares byte for byte. A target's result is also the answer to the client.

Encoding a target's result dict cost the service more than its search: the
generic encoder walks the dict and formats every float, and several floats
repeat (for the routing objective the cost is also the objective and the
time). :meth:`TargetResult.to_json` writes the same text from a fixed template,
and :func:`target_payload` the event's payload.
Anything the template does not cover (a value that is not a plain finite
float, int or string, a position described with other keys) goes to the
canonical encoder, which also raises for NaN and infinity.
``tests/service/test_canonical.py`` checks the template against the encoder.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from json.encoder import encode_basestring_ascii
from typing import Any, NamedTuple

__all__ = ["TargetResult", "dumps", "result_cost", "target_payload"]

_CANONICAL = json.JSONEncoder(separators=(",", ":"), sort_keys=True, allow_nan=False)


def dumps(data: Any) -> str:
    """Canonical JSON text (exact float round trip, stable key order).

    What ``json.dumps(data, separators=(",", ":"), sort_keys=True,
    allow_nan=False)`` gives, with one encoder kept instead of one per call.
    """
    return _CANONICAL.encode(data)


_text = encode_basestring_ascii
_float_repr = float.__repr__


class _Untemplated(Exception):
    """A value the template does not write; the canonical encoder does."""


def _number(value: object) -> str:
    if type(value) is float and value - value == 0.0:  # finite
        return _float_repr(value)
    if type(value) is int:
        return int.__repr__(value)
    raise _Untemplated


def _same_as(value: object, written: float, text: str) -> str:
    """``_number(value)``, taken from ``text`` (the float ``written``, written already)
    when ``value`` is written the same: the same object, or an equal float with the same
    sign of zero."""
    if value is written:
        return text
    if (
        type(value) is float
        and value == written
        and (written != 0.0 or math.copysign(1.0, value) == math.copysign(1.0, written))
    ):
        return text
    return _number(value)


def _string(value: object) -> str:
    if type(value) is not str:
        raise _Untemplated
    return _text(value)


def _requires(requires: list[str] | None) -> str:
    return "null" if requires is None else f"[{','.join(map(_string, requires))}]"


def target_payload(target: dict[str, Any], requires: list[str] | None) -> str:
    """A target event's payload, ``dumps({"target": target, "requires": requires})``,
    written from a template.

    ``target`` is an encoded position (``{"edge", "offset"}``); anything else goes to
    the canonical encoder, which also raises for a NaN or infinite offset.
    """
    try:
        if len(target) == 2:
            return (
                f'{{"requires":{_requires(requires)},"target":{{"edge":'
                f'{_string(target["edge"])},"offset":{_number(target["offset"])}}}}}'
            )
    except (_Untemplated, KeyError):
        pass
    return dumps({"target": target, "requires": requires})


def _position(described: dict[str, Any]) -> str:
    """``{"edge", "offset", "x", "y"}`` with ``"lon", "lat"`` or without, keys sorted."""
    if len(described) == 6:
        return (
            f'{{"edge":{_string(described["edge"])},"lat":{_number(described["lat"])},'
            f'"lon":{_number(described["lon"])},"offset":{_number(described["offset"])},'
            f'"x":{_number(described["x"])},"y":{_number(described["y"])}}}'
        )
    if len(described) == 4:
        return (
            f'{{"edge":{_string(described["edge"])},"offset":{_number(described["offset"])},'
            f'"x":{_number(described["x"])},"y":{_number(described["y"])}}}'
        )
    raise _Untemplated


def _dispatch(dispatch: dict[str, Any], cost: float, cost_text: str) -> str:
    """``{"cost", "missing", "status", "vehicles": [{"cost", "type", "vehicle"}]}`` (the
    dispatch answer, :meth:`routing_svc.sa.live.Sent.to_dict`), keys sorted; a cost equal
    to the learning answer's ``cost`` is written from ``cost_text``."""
    if len(dispatch) != 4:
        raise _Untemplated
    total = dispatch["cost"]
    vehicles = []
    for sent in dispatch["vehicles"]:
        if len(sent) != 3:
            raise _Untemplated
        vehicles.append(
            f'{{"cost":{_same_as(sent["cost"], cost, cost_text)},'
            f'"type":{_string(sent["type"])},"vehicle":{_string(sent["vehicle"])}}}'
        )
    return (
        f'{{"cost":{"null" if total is None else _same_as(total, cost, cost_text)},'
        f'"missing":[{",".join(map(_string, dispatch["missing"]))}],'
        f'"status":{_string(dispatch["status"])},"vehicles":[{",".join(vehicles)}]}}'
    )


class TargetResult(NamedTuple):
    """The result of a target event: what the client gets and the event log keeps.

    ``target`` and ``new_position`` are described positions (``edge, offset, x, y``
    and ``lon, lat`` where the network has a projection); ``new_position`` may be
    the ``target`` object itself. ``backed_off`` lists ``(vehicle id, described
    position)``. ``dispatch`` is the dispatch answer (who goes now,
    :meth:`routing_svc.sa.live.Sent.to_dict`); ``None`` only for results stored before
    it existed, which replay writes again without it.
    """

    seq: int
    target: dict[str, Any]
    requires: list[str] | None
    served_by: Sequence[str]
    times: Sequence[float]
    moved: str
    cost: float
    objective: float
    step_size: float
    moved_by: float
    noise: float
    new_position: dict[str, Any]
    backed_off: Sequence[tuple[str, dict[str, Any]]]
    consolidated: dict[str, Any] | None = None
    dispatch: dict[str, Any] | None = None

    def as_dict(self) -> dict[str, Any]:
        """The result as the API documents it (``version`` is ``seq``)."""
        extra = {} if self.consolidated is None else {"consolidated": self.consolidated}
        if self.dispatch is not None:
            extra["dispatch"] = self.dispatch
        return extra | {
            "seq": self.seq,
            "version": self.seq,
            "target": self.target,
            "requires": self.requires,
            "served_by": list(self.served_by),
            "times": list(self.times),
            "moved": self.moved,
            "cost": self.cost,
            "objective": self.objective,
            "step_size": self.step_size,
            "moved_by": self.moved_by,
            "noise": self.noise,
            "new_position": self.new_position,
            "backed_off": [{"position": p, "vehicle": v} for v, p in self.backed_off],
        }

    def to_json(self) -> str:
        """``dumps(self.as_dict())``, written from a template.

        Raises
        ------
        ValueError
            For a NaN or infinite float (as the canonical encoder does).
        """
        try:
            return self._templated()
        except _Untemplated:
            return dumps(self.as_dict())

    def _templated(self) -> str:
        if self.consolidated is not None:
            raise _Untemplated
        cost = self.cost
        cost_text = _number(cost)
        dispatch_text = "" if self.dispatch is None else _dispatch(self.dispatch, cost, cost_text)
        seq_text = _number(self.seq)
        target_text = _position(self.target)
        new_position = self.new_position
        requires = self.requires
        return "".join(
            (
                '{"backed_off":[',
                ",".join(
                    [
                        f'{{"position":{_position(p)},"vehicle":{_string(v)}}}'
                        for v, p in self.backed_off
                    ]
                ),
                '],"cost":',
                cost_text,
                "" if self.dispatch is None else ',"dispatch":' + dispatch_text,
                ',"moved":',
                _string(self.moved),
                ',"moved_by":',
                _number(self.moved_by),
                ',"new_position":',
                target_text if new_position is self.target else _position(new_position),
                ',"noise":',
                _number(self.noise),
                ',"objective":',
                _same_as(self.objective, cost, cost_text),
                ',"requires":',
                _requires(requires),
                ',"seq":',
                seq_text,
                ',"served_by":[',
                ",".join(map(_string, self.served_by)),
                '],"step_size":',
                _number(self.step_size),
                ',"target":',
                target_text,
                ',"times":[',
                ",".join([_same_as(t, cost, cost_text) for t in self.times]),
                '],"version":',
                seq_text,
                "}",
            )
        )


_COST_AFTER_BACKED_OFF = '],"cost":'


def result_cost(text: str) -> float:
    """The ``cost`` of a target result's JSON text (:meth:`TargetResult.to_json`).

    Read where the template writes it, right after ``backed_off``: no value of a
    described position is a list and strings are escaped, so the first ``],"`` closes
    ``backed_off``. A result laid out otherwise (one that holds a consolidation) is
    parsed whole.
    """
    if text.startswith('{"backed_off":['):
        end = text.find('],"', 15)
        if text.startswith(_COST_AFTER_BACKED_OFF, end):
            start = end + len(_COST_AFTER_BACKED_OFF)
            return float(text[start : text.index(",", start)])
    return float(json.loads(text)["cost"])
