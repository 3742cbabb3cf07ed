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

A fleet's state snapshot is not an event: it is written by orjson
(:func:`state_dumps`) and compared by value (:func:`same_state`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from json.encoder import encode_basestring_ascii
from operator import itemgetter
from typing import Any, NamedTuple

import orjson

__all__ = [
    "TargetResult",
    "dumps",
    "dumps_finite",
    "result_cost",
    "same_state",
    "state_dumps",
    "target_payload",
]

_CANONICAL = json.JSONEncoder(separators=(",", ":"), sort_keys=True, allow_nan=False)


def dumps(data: Any) -> str:
    """Canonical JSON text (exact float round trip, stable key order).

    What ``json.dumps(data, separators=(",", ":"), sort_keys=True,
    allow_nan=False)`` gives, with one encoder kept instead of one per call.
    """
    return _CANONICAL.encode(data)


_FLOAT_MARKS = (b"e-", b"e1", b"e2", b"e3", b"0.0000")
"""Marks of a finite float that orjson may write otherwise than ``repr`` (and
:func:`dumps`): magnitudes below :data:`_FIXED_LOW` (``e-`` or ``0.0000...``, where
``repr`` writes ``e-05``), and an exponent from :data:`_FIXED_HIGH` on without its sign
(``e16`` to ``e308``; orjson writes ``e+16`` there, as ``repr`` does, and the marks only
guard against the form)."""

_ORJSON_ONLY = (b"\x7f", *_FLOAT_MARKS)
"""What orjson writes where :func:`dumps` writes otherwise, in an ASCII text: DEL
unescaped, and :data:`_FLOAT_MARKS`."""

_NOT_PLAIN_NUMBERS = (b"e", b"n", b"0.0000", b'"', b"[", b"{")
"""Marks of an orjson list that holds something other than plain numbers written as
``repr`` writes them: every mark of :data:`_FLOAT_MARKS` holds one of them (``e`` or
``0.0000``), and ``null``, ``true``, ``false``, strings and nested values hold one too."""


def dumps_finite(data: Any) -> str:
    """:func:`dumps` of JSON data whose floats are all finite (a validated request body).

    Written by orjson, and by :func:`dumps` again where orjson's text could differ:
    any non-ASCII text or a mark of :data:`_ORJSON_ONLY` (found also inside strings,
    where it only costs the second writing). orjson writes a non-finite float as
    ``null``, where :func:`dumps` raises: hence the precondition.
    """
    try:
        raw = orjson.dumps(
            data,
            option=orjson.OPT_SORT_KEYS
            | orjson.OPT_PASSTHROUGH_DATACLASS
            | orjson.OPT_PASSTHROUGH_DATETIME,
        )
    except orjson.JSONEncodeError:
        return dumps(data)
    if not raw.isascii() or any(mark in raw for mark in _ORJSON_ONLY):
        return dumps(data)
    return raw.decode()


def state_dumps(data: Any) -> str:
    """JSON text of a fleet's state snapshot: sorted keys, exact float round trip.

    Snapshots are the largest texts the write path writes (a ``consolidating``
    fleet's reservoir), and are compared by :func:`same_state`, not byte for byte,
    so they are written by orjson. Its floats are the shortest round-trip digits as
    :func:`dumps` writes them, with other exponent forms (``1e-7`` for ``1e-07``),
    and its strings are UTF-8. A fleet's state holds finite floats only (every
    input is checked); orjson would write a non-finite one as ``null``, which
    :func:`same_state` then finds different from the replayed state.
    """
    return orjson.dumps(data, option=orjson.OPT_SORT_KEYS).decode()


def same_state(first: str, second: str) -> bool:
    """Whether two JSON texts hold the same values, floats bit for bit (``-0.0`` is not
    ``0.0``), whichever encoder wrote them (:func:`dumps` or :func:`state_dumps`)."""
    if first == second:
        return True
    return _normal(first) == _normal(second)


def _normal(text: str) -> bytes:
    return orjson.dumps(orjson.loads(text), option=orjson.OPT_SORT_KEYS)


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


_FIXED_LOW, _FIXED_HIGH = 1e-4, 1e16
"""Magnitudes ``repr`` writes without an exponent, where orjson writes the same digits."""


def _numbers(values: Sequence[object]) -> list[str]:
    """``[_number(v) for v in values]``, the floats written by one orjson call.

    orjson writes the shortest round-trip digits, as ``repr`` does; the two differ
    only in the exponent form, which ``repr`` uses for magnitudes below
    :data:`_FIXED_LOW` or from :data:`_FIXED_HIGH` on. orjson writes those with an
    ``e`` or as ``0.0000...``, a non-finite float as ``null``, ``true`` and ``false``
    with an ``e``, strings and nested values with quotes or brackets; a list free of
    these marks (:data:`_NOT_PLAIN_NUMBERS`) holds numbers written as ``repr`` writes
    them. Otherwise each value is
    written by :func:`_number` (which raises for what the template does not write).
    """
    try:
        raw = orjson.dumps(values)
    except orjson.JSONEncodeError:
        return [_number(v) for v in values]
    inner = raw[1:-1]
    e, n, low, quote, bracket, brace = _NOT_PLAIN_NUMBERS
    if not (
        e in inner
        or n in inner
        or low in inner
        or quote in inner
        or bracket in inner
        or brace in inner
    ):
        texts = inner.decode().split(",")
        if len(texts) == len(values):
            return texts
    texts = inner.decode().split(",")
    if len(texts) != len(values):
        return [_number(v) for v in values]
    for i, v in enumerate(values):
        if type(v) is not float or not (_FIXED_LOW <= abs(v) < _FIXED_HIGH or v == 0.0):
            texts[i] = _number(v)
    return texts


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


_GEO_KEYS = ("lat", "lon", "offset", "x", "y")
_PLANE_KEYS = ("offset", "x", "y")
_geo_floats = itemgetter(*_GEO_KEYS)
_plane_floats = itemgetter(*_PLANE_KEYS)


def _position_floats(described: dict[str, Any]) -> tuple[Any, ...]:
    """The numbers of a described position, in the order :func:`_position` writes them."""
    if len(described) == 6:
        return _geo_floats(described)  # type: ignore[no-any-return]
    if len(described) == 4:
        return _plane_floats(described)  # type: ignore[no-any-return]
    raise _Untemplated


def _position(described: dict[str, Any], numbers: Sequence[str] | None = None) -> str:
    """``{"edge", "offset", "x", "y"}`` with ``"lon", "lat"`` or without, keys sorted;
    ``numbers``: its :func:`_position_floats` written already."""
    if numbers is None:
        numbers = _numbers(_position_floats(described))
    edge = _string(described["edge"])
    if len(numbers) == 5 and len(described) == 6:
        lat, lon, offset, x, y = numbers
        return f'{{"edge":{edge},"lat":{lat},"lon":{lon},"offset":{offset},"x":{x},"y":{y}}}'
    if len(numbers) == 3 and len(described) == 4:
        offset, x, y = numbers
        return f'{{"edge":{edge},"offset":{offset},"x":{x},"y":{y}}}'
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
        target, new_position = self.target, self.new_position
        at_target = new_position is target
        target_floats = _position_floats(target)
        moved_floats = [] if at_target else _position_floats(new_position)
        cost_text, moved_by_text, noise_text, step_size_text, *positions = _numbers(
            [cost, self.moved_by, self.noise, self.step_size, *target_floats, *moved_floats]
        )
        dispatch_text = "" if self.dispatch is None else _dispatch(self.dispatch, cost, cost_text)
        seq_text = _number(self.seq)
        target_text = _position(target, positions[: len(target_floats)])
        new_position_text = (
            target_text if at_target else _position(new_position, positions[len(target_floats) :])
        )
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
                moved_by_text,
                ',"new_position":',
                new_position_text,
                ',"noise":',
                noise_text,
                ',"objective":',
                _same_as(self.objective, cost, cost_text),
                ',"requires":',
                _requires(requires),
                ',"seq":',
                seq_text,
                ',"served_by":[',
                ",".join(map(_string, self.served_by)),
                '],"step_size":',
                step_size_text,
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
