"""A target's result and payload written from their templates are exactly the canonical JSON
of their dicts."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import orjson
import pytest

from routing_svc.service.canonical import (
    _FLOAT_MARKS,
    _NOT_PLAIN_NUMBERS,
    TargetResult,
    dumps,
    dumps_finite,
    result_cost,
    same_state,
    state_dumps,
    target_payload,
)

_STRINGS = [
    "v01", "-157539101#0", 'quote"back\\slash', "Zürich/Straße", "tab\tnew\nline", "🚕",
    '],"cost":9,"x',
]  # fmt: skip


# floats at the edges of the spellings: zeros, exponents, both sides of 1e-4 and 1e16
_EDGES = [0.0, -0.0, 1.0, 1e-5, 1.5e-300, 123456789.0, 1e-4, -1e-4, 9.999999999999999e-05]
_EDGES += [1e16, 9999999999999998.0]


def _float(rng: np.random.Generator) -> float:
    """Floats of every kind the encoder writes differently: exponents, zeros, integers."""
    kind = rng.integers(7)
    if kind == 0:
        while True:  # any finite double, from random bits
            value = float(rng.integers(0, 2**63, dtype=np.int64).view(np.float64))
            if math.isfinite(value):
                return value * (1 if rng.random() < 0.5 else -1)
    if kind == 1:
        return float(rng.choice(_EDGES))
    if kind == 2:
        return float(np.round(rng.uniform(0, 1e4), int(rng.integers(0, 6))))
    return float(rng.uniform(0.0, 10.0 ** rng.integers(-6, 18)))


def _position(rng: np.random.Generator) -> dict[str, Any]:
    described: dict[str, Any] = {
        "edge": str(rng.choice(_STRINGS)),
        "offset": _float(rng),
        "x": _float(rng),
        "y": _float(rng),
    }
    if rng.random() < 0.7:
        described["lon"], described["lat"] = _float(rng), _float(rng)
    return described


def _dispatch(rng: np.random.Generator, cost: float) -> dict[str, Any] | None:
    """A dispatch answer (or none, as in results stored before it existed)."""
    if rng.random() < 0.2:
        return None
    sent = [
        {
            "vehicle": str(rng.choice(_STRINGS)),
            "type": str(rng.choice(["*", *_STRINGS])),
            "cost": cost if rng.random() < 0.5 else _float(rng),
        }
        for _ in range(int(rng.integers(0, 3)))
    ]
    missing = [] if rng.random() < 0.7 else [str(rng.choice(_STRINGS))]
    done = sent and not missing
    return {
        "status": "dispatched" if done else "partial" if sent else "queued",
        "vehicles": sent,
        "missing": missing,
        "cost": (cost if rng.random() < 0.5 else _float(rng)) if done else None,
    }


def _arguments(rng: np.random.Generator) -> dict[str, Any]:
    cost = _float(rng)
    target = _position(rng)
    n_served = int(rng.integers(1, 4))
    kind = rng.integers(3)
    objective = cost if kind == 0 else float(cost**1.0) if kind == 1 else _float(rng)
    return {
        "seq": int(rng.integers(2, 10**12)),
        "target": target,
        "requires": None if rng.random() < 0.6 else [str(rng.choice(_STRINGS)) for _ in range(2)],
        "served_by": [str(rng.choice(_STRINGS)) for _ in range(n_served)],
        "times": [cost if rng.random() < 0.5 else _float(rng) for _ in range(n_served)],
        "moved": str(rng.choice(_STRINGS)),
        "cost": cost,
        "objective": objective,
        "step_size": _float(rng),
        "moved_by": _float(rng),
        "noise": 0.0 if rng.random() < 0.8 else _float(rng),
        "new_position": target if rng.random() < 0.2 else _position(rng),
        "backed_off": [
            (str(rng.choice(_STRINGS)), _position(rng)) for _ in range(int(rng.integers(0, 3)))
        ],
        "dispatch": _dispatch(rng, cost),
    }


def test_template_writes_the_canonical_json() -> None:
    rng = np.random.default_rng(11)
    for _ in range(20_000):
        arguments = _arguments(rng)
        text = TargetResult(**arguments).to_json()
        assert text == dumps(TargetResult(**arguments).as_dict())
        assert json.loads(text)["cost"] == arguments["cost"]


def test_the_cost_read_from_a_result_is_the_cost_it_holds() -> None:
    rng = np.random.default_rng(17)
    consolidated = {"accepted": True, "cost": 5.0, "positions": [], "sample": [1], "z": [2.5]}
    for k in range(20_000):
        arguments = _arguments(rng)
        if k % 10 == 0:  # written by the encoder, "consolidated" before "cost"
            arguments["consolidated"] = consolidated
        text = TargetResult(**arguments).to_json()
        cost = result_cost(text)
        assert cost == json.loads(text)["cost"]
        assert math.copysign(1.0, cost) == math.copysign(1.0, arguments["cost"])


def test_the_dict_is_the_result_the_api_documents() -> None:
    rng = np.random.default_rng(12)
    arguments = _arguments(rng)
    arguments["backed_off"] = [("v07", arguments["target"])]
    arguments["dispatch"] = {"status": "queued", "vehicles": [], "missing": ["*"], "cost": None}
    result = json.loads(TargetResult(**arguments).to_json())
    assert result["dispatch"] == arguments["dispatch"]
    assert result["seq"] == result["version"] == arguments["seq"]
    assert result["backed_off"] == [{"vehicle": "v07", "position": arguments["target"]}]
    assert set(result) == {
        "seq", "version", "target", "requires", "served_by", "times", "moved", "cost",
        "objective", "step_size", "moved_by", "noise", "new_position", "backed_off", "dispatch",
    }  # fmt: skip


def test_same_zero_is_not_taken_for_the_other() -> None:
    rng = np.random.default_rng(13)
    arguments = _arguments(rng)
    arguments.update(cost=0.0, objective=-0.0, times=[-0.0])
    text = TargetResult(**arguments).to_json()
    assert '"cost":0.0' in text and '"objective":-0.0' in text and '"times":[-0.0]' in text
    assert text == dumps(TargetResult(**arguments).as_dict())


@pytest.mark.parametrize(
    "change",
    [
        {"cost": math.nan},
        {"moved_by": math.inf},
        {"step_size": -math.inf},
        {"times": [math.nan]},
        {"dispatch": {"status": "dispatched", "vehicles": [], "missing": [], "cost": math.inf}},
    ],
)
def test_nan_and_infinity_raise_like_the_encoder(change: dict[str, Any]) -> None:
    arguments = {**_arguments(np.random.default_rng(14)), **change}
    with pytest.raises(ValueError, match="JSON compliant"):
        TargetResult(**arguments).to_json()


@pytest.mark.parametrize(
    "change",
    [
        {"cost": np.float64(3.25)},  # a float subclass
        {"step_size": 2},  # an int
        {"noise": True},  # a bool is not an int here
        {"moved": None},
        {"target": {"edge": "e", "offset": 1.0, "x": 2.0, "y": 3.0, "z": 4.0}},
        {"new_position": {"edge": "e", "offset": 1.0, "x": 2.0, "y": 3.0, "lon": 4.0}},
        {"dispatch": {"status": "queued", "vehicles": [], "missing": [], "cost": None, "x": 1}},
        {
            "dispatch": {
                "status": "queued",
                "vehicles": [{"vehicle": "v"}],
                "missing": [],
                "cost": 2,
            }
        },
    ],
)
def test_what_the_template_does_not_cover_goes_to_the_encoder(change: dict[str, Any]) -> None:
    arguments = {**_arguments(np.random.default_rng(15)), **change}
    assert TargetResult(**arguments).to_json() == dumps(TargetResult(**arguments).as_dict())


def test_the_payload_template_writes_the_canonical_json() -> None:
    rng = np.random.default_rng(16)
    for _ in range(20_000):
        target = {"edge": str(rng.choice(_STRINGS)), "offset": _float(rng)}
        requires = (
            None
            if rng.random() < 0.5
            else [str(rng.choice(_STRINGS)) for _ in range(int(rng.integers(0, 3)))]
        )
        text = target_payload(target, requires)
        assert text == dumps({"target": target, "requires": requires})
        assert json.loads(text) == {"target": target, "requires": requires}


@pytest.mark.parametrize(
    "target",
    [
        {"edge": "e", "offset": 2},  # an int offset
        {"edge": "e", "offset": np.float64(0.5)},  # a float subclass
        {"edge": "e", "x": 1.0},  # other keys
        {"edge": "e", "offset": 1.0, "lane": 0},
        {"edge": 7, "offset": 1.0},  # not a string
    ],
)
def test_a_payload_the_template_does_not_cover_goes_to_the_encoder(target: dict[str, Any]) -> None:
    assert target_payload(target, ["A"]) == dumps({"target": target, "requires": ["A"]})


@pytest.mark.parametrize("offset", [math.nan, math.inf, -math.inf])
def test_a_payload_with_nan_or_infinity_raises_like_the_encoder(offset: float) -> None:
    with pytest.raises(ValueError, match="JSON compliant"):
        target_payload({"edge": "e", "offset": offset}, None)


def _state(rng: np.random.Generator) -> dict[str, Any]:
    """A nested state of the shapes a fleet's snapshot has, floats of every kind."""
    return {
        "positions": [_position(rng) for _ in range(int(rng.integers(0, 6)))],
        "learning": {"baseline": None if rng.random() < 0.3 else _float(rng), "epoch": 7},
        "recent": [_float(rng) for _ in range(int(rng.integers(0, 6)))],
        "deleted": bool(rng.random() < 0.5),
    }


def _floats_exactly(value: Any) -> Any:
    """``value`` with each float as its bits (``==`` then tells ``-0.0`` from ``0.0``)."""
    if isinstance(value, float):
        return ("float", float.hex(value))
    if isinstance(value, dict):
        return {k: _floats_exactly(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_floats_exactly(v) for v in value]
    return value


def test_a_state_text_holds_the_state_bit_for_bit() -> None:
    rng = np.random.default_rng(21)
    for _ in range(5_000):
        state = _state(rng)
        text = state_dumps(state)
        assert _floats_exactly(json.loads(text)) == _floats_exactly(state)
        assert list(json.loads(text)) == sorted(state)
        assert same_state(text, dumps(state))  # a snapshot stored by the canonical encoder


def test_states_that_differ_in_one_float_are_not_the_same() -> None:
    rng = np.random.default_rng(22)
    for _ in range(2_000):
        state = _state(rng)
        state["recent"] = [*state["recent"], _float(rng)]
        other = json.loads(json.dumps(state))
        last = other["recent"][-1]
        other["recent"][-1] = -last if last == 0.0 else math.nextafter(last, math.inf)
        assert not same_state(state_dumps(state), state_dumps(other))
        assert not same_state(dumps(state), state_dumps(other))


def test_key_order_and_float_spelling_do_not_make_states_differ() -> None:
    assert same_state('{"b":[1e-07,2.5],"a":null}', '{"a":null,"b":[1e-7,2.5]}')
    assert not same_state('{"a":0.0}', '{"a":-0.0}')
    assert not same_state('{"a":1}', '{"a":1.0}')


def _body(rng: np.random.Generator, depth: int = 0) -> Any:
    """A JSON value with finite floats, strings of every kind (DEL, non-ASCII, the marks
    of an exponent), big and small integers, booleans and nulls, nested."""
    kind = int(rng.integers(9 if depth < 3 else 6))
    if kind == 0:
        return _float(rng)
    if kind == 1:
        return str(rng.choice([*_STRINGS, "del\x7f", "e-5", "ve12", "0.00001", "null"]))
    if kind == 2:
        return int(rng.choice([0, -7, 2**53 + 1, 2**63 - 1, 2**64, -(2**70)]))
    if kind == 3:
        return bool(rng.random() < 0.5)
    if kind == 4:
        return None
    if kind == 5:
        return _float(rng)
    if kind in (6, 7):
        keys = [*_STRINGS, "offset", "edge", "requires", "e3"]
        return {str(rng.choice(keys)): _body(rng, depth + 1) for _ in range(rng.integers(0, 4))}
    return [_body(rng, depth + 1) for _ in range(int(rng.integers(0, 4)))]


def test_orjson_writes_a_float_otherwise_than_repr_only_with_a_float_mark() -> None:
    rng = np.random.default_rng(29)
    differing = 0
    for exponent in range(-324, 309):
        for mantissa in (1.0, 5.0, float(rng.uniform(1.0, 10.0))):
            value = mantissa * 10.0**exponent
            if not math.isfinite(value):
                continue
            for v in (value, -value):
                text = orjson.dumps(v)
                if text.decode() != repr(v):
                    differing += 1
                    assert any(mark in text for mark in _FLOAT_MARKS), (v, text)
    # repr writes an exponent of two digits (1e-07) where orjson writes one (1e-7) or
    # fixed digits: from 1e-9 to below 1e-4, 5 decades of 3 mantissas and 2 signs
    assert differing == 30
    # the coarse check of a list of numbers sees every one of these marks
    for mark in _FLOAT_MARKS:
        assert any(coarse in mark for coarse in _NOT_PLAIN_NUMBERS), mark


def test_a_finite_body_is_written_as_the_canonical_encoder_writes_it() -> None:
    rng = np.random.default_rng(23)
    for _ in range(20_000):
        body = _body(rng)
        assert dumps_finite(body) == dumps(body)
    plain = [round(float(rng.uniform(0, 300)), 2) for _ in range(2_000)]  # orjson's text
    every_kind = [_float(rng) for _ in range(2_000)]  # the encoder's text
    for offsets in (plain, every_kind):
        targets = [
            {"position": {"edge": "-157539101#0", "offset": offset}, "requires": None}
            for offset in offsets
        ]
        assert dumps_finite({"targets": targets}) == dumps({"targets": targets})
