"""Tracking a slowly moving optimum: decreasing vs asymptotically constant steps (III-D).

Decreasing steps (``sum gamma_k**2 < inf``) make the iterates converge when
the optimum is fixed, but freeze them when it moves; a step with a positive
floor keeps a bounded lag (section III-D of the paper). Two settings, each
with the three step rules *decreasing*, *floor* (decreasing to a floor) and
*constant*:

- *source*: a single robot seeks the minimum of the field of
  :mod:`routing_svc.paper.source_seeking` with SPSA (eq. (18)) while the
  source moves on a circle of radius ``radius`` (one turn in ``periods``);
- *fleet*: three routing vehicles (``Fleet``, eq. (10)) serve a mixture of
  two fixed hotspots (20 % each) and one hotspot (60 %) moving on a circle
  (``turns`` turns over the stream); we record the distance from the moving
  hotspot's centre to its nearest vehicle.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from routing_svc.paper.plane_demand import Hotspot, Mixture, feed, plane_fleet
from routing_svc.paper.result import ExperimentResult, quantile_band, seed_generators, thinned
from routing_svc.paper.source_seeking import SourceField
from routing_svc.sa import ROUTING, Constant, FleetConfig, Floor, InverseScaling, Schedule
from routing_svc.sa.estimators import SpsaGains, spsa_gradient
from routing_svc.types import FloatArray

RULES = ("decreasing", "floor", "constant")
SIDE = 10.0
CIRCLE_CENTRE = np.array([5.0, 5.0])


def circle(t: FloatArray, *, radius: float, turns: float) -> FloatArray:
    """Points on the circle around (5, 5) at fractions ``t`` in [0, 1] of the run."""
    angle = 2.0 * np.pi * turns * np.asarray(t)
    return np.asarray(
        CIRCLE_CENTRE + radius * np.stack([np.cos(angle), np.sin(angle)], axis=-1),
        dtype=np.float64,
    )


def source_gains(rule: str) -> SpsaGains:
    """The SPSA gains of a step rule: ``a_k`` decreasing, floored, or constant."""
    decreasing = SpsaGains(a=1.5, c=0.4, alpha=0.602, gamma=0.101, stability=10.0)
    if rule == "decreasing":
        return decreasing
    if rule == "floor":
        return replace(decreasing, floor=0.15)
    return SpsaGains(a=0.15, c=0.4, alpha=0.0, gamma=0.101)


def follow_source(
    rule: str, *, periods: int, radius: float, rng: np.random.Generator
) -> FloatArray:
    """Distance from a single SPSA robot to the moving source in every period."""
    gains = source_gains(rule)
    sources = circle(np.arange(periods + 1) / periods, radius=radius, turns=1.0)
    x = np.array([1.0, 1.0])
    errors = np.empty(periods + 1)
    errors[0] = np.hypot(*(x - sources[0]))
    for k in range(periods):
        field = SourceField(source=(float(sources[k][0]), float(sources[k][1])))
        g = spsa_gradient(field.measure, x, c=gains.perturbation(k), rng=rng)
        x = x - gains.step(k) * g
        errors[k + 1] = np.hypot(*(x - sources[k + 1]))
    return errors


def fleet_schedule(rule: str, *, scale: float) -> Schedule:
    """The fleet's step rule: decreasing (the default), floored, or constant."""
    decreasing = InverseScaling(scale, 0.75)
    if rule == "decreasing":
        return decreasing
    if rule == "floor":
        return Floor(decreasing, 0.05)
    return Constant(0.05)


def follow_hotspot(
    rule: str, *, targets: int, turns: float, radius: float, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray]:
    """Distance from the moving hotspot to its nearest vehicle at checkpoints."""
    fixed = (Hotspot((2.0, 8.0), 0.6, 0.2), Hotspot((8.0, 2.0), 0.6, 0.2))
    fractions = np.arange(targets) / targets
    moving = circle(fractions, radius=radius, turns=turns)
    which = rng.choice(3, size=targets, p=[0.2, 0.2, 0.6])
    stream = rng.standard_normal((targets, 2)) * 0.6
    stream[which == 0] += fixed[0].centre
    stream[which == 1] += fixed[1].centre
    stream[which == 2] += moving[which == 2]
    scale = 0.5 * SIDE / np.sqrt(3.0)
    config = FleetConfig(ROUTING, fleet_schedule(rule, scale=scale))
    start = Mixture(fixed).sample(rng, 1)[0]
    fleet = plane_fleet(
        np.vstack([fixed[0].centre, fixed[1].centre, start]), config=config, side=SIDE
    )
    marks = np.linspace(0, targets, 101).astype(int)
    snapshots = feed(fleet, stream, checkpoints=marks.tolist())
    centres = circle(marks / targets, radius=radius, turns=turns)
    lag = np.array([np.hypot(*(s - c).T).min() for s, c in zip(snapshots, centres, strict=True)])
    return marks.astype(np.float64), lag


def run(*, seeds: int, quick: bool, seed: int = 0) -> ExperimentResult:
    """Both settings, each step rule, over ``seeds`` seeds."""
    periods = 1500 if quick else 4000
    targets = 6000 if quick else 30_000
    radius, turns = 2.5, 2.0
    source: dict[str, Any] = {}
    fleet: dict[str, Any] = {}
    marks: FloatArray = np.zeros(0)
    for rule in RULES:
        generators = seed_generators(seed, seeds)
        source[rule] = np.array(
            [follow_source(rule, periods=periods, radius=radius, rng=rng) for rng in generators]
        )
        lags = []
        for rng in generators:
            marks, lag = follow_hotspot(rule, targets=targets, turns=turns, radius=radius, rng=rng)
            lags.append(lag)
        fleet[rule] = np.array(lags)
    tail = slice(-(periods // 4), None)
    fleet_tail = slice(-25, None)
    keep = thinned(periods + 1)
    summary: dict[str, Any] = {}
    for rule in RULES:
        summary[f"source_{rule}_last_quarter_mean_error"] = float(source[rule][:, tail].mean())
        summary[f"fleet_{rule}_last_quarter_mean_lag"] = float(fleet[rule][:, fleet_tail].mean())
    return ExperimentResult(
        name="tracking",
        title="Tracking a moving optimum: decreasing vs asymptotically constant steps",
        params={
            "seeds": seeds,
            "seed": seed,
            "periods": periods,
            "targets": targets,
            "circle_radius": radius,
            "fleet_turns": turns,
            "source_turns": 1.0,
            "source_gains": {rule: source_gains(rule).__repr__() for rule in RULES},
            "fleet_schedules": {
                rule: fleet_schedule(rule, scale=0.5 * SIDE / np.sqrt(3.0)).to_dict()
                for rule in RULES
            },
        },
        summary=summary,
        series={
            "period": keep,
            "source": {rule: quantile_band(source[rule], keep=keep) for rule in RULES},
            "marks": marks,
            "fleet": {rule: quantile_band(fleet[rule]) for rule in RULES},
        },
    )
