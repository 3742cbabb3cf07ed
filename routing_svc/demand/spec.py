"""The one parser of demand specs, and the one builder of their distributions.

Every command that takes ``--demand`` (``simulate``, ``optimum``, ``cosim``)
reads it with :func:`parse_demand_spec`; the service's reference demand (a
JSON object) becomes the same :class:`DemandRecipe` with
:func:`recipe_from_reference`. :func:`network_demand` builds the
distribution on a road network.

Grammar::

    SPEC    := FORM [ "?profile=" PROFILE ]
    FORM    := "uniform"                 demand uniform over road length
             | "hotspots" [ ":" K ]      K Gaussian hotspots (K >= 1, default 3)
             | "weights:" FILE           edge_id,weight CSV or {"edge_id": weight} JSON
             | "buildings:" FILE         buildings CSV (columns Weight, GenEdge)
             | FILE                      an existing weights file (the first form of it)
    PROFILE := a file of 24 hourly weights (see routing_svc.demand.profile)

The profile says how the rate of requests varies over the day; it does not
change where targets are, so only the co-simulation, whose requests have
times, uses it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from routing_svc.demand.distribution import DemandDistribution
from routing_svc.demand.profile import HourlyProfile, read_profile
from routing_svc.errors import InvalidInput, UnknownEdge
from routing_svc.network import CompiledNetwork
from routing_svc.types import NetPosition

__all__ = [
    "DEFAULT_HOTSPOTS",
    "BuildingsFile",
    "DemandForm",
    "DemandRecipe",
    "EdgeWeights",
    "Hotspots",
    "Uniform",
    "WeightsFile",
    "network_demand",
    "parse_demand_spec",
    "recipe_from_reference",
]

DEFAULT_HOTSPOTS = 3
"""Hotspots of ``hotspots`` without a count."""

SPEC_FORMS = "'uniform', 'hotspots[:K]', 'weights:FILE' (or an existing weights file) or "
SPEC_FORMS += "'buildings:FILE', each optionally followed by '?profile=FILE'"


@dataclass(frozen=True, slots=True)
class Uniform:
    """Demand uniform over the length of every road."""


@dataclass(frozen=True, slots=True)
class Hotspots:
    """``count`` Gaussian hotspots of standard deviation ``spread`` (metres; default 10 %
    of the bounding-box diagonal), centres drawn with the builder's ``rng``."""

    count: int = DEFAULT_HOTSPOTS
    spread: float | None = None


@dataclass(frozen=True, slots=True)
class WeightsFile:
    """A weight per edge id from a CSV or JSON file."""

    path: Path


@dataclass(frozen=True, slots=True)
class EdgeWeights:
    """A weight per edge id given in memory (the service's reference demand)."""

    weights: Mapping[str, float]


@dataclass(frozen=True, slots=True)
class BuildingsFile:
    """A weight per building on its nearest drivable edge, from a buildings CSV."""

    path: Path


DemandForm = Uniform | Hotspots | WeightsFile | EdgeWeights | BuildingsFile


@dataclass(frozen=True, slots=True)
class DemandRecipe:
    """A parsed demand spec: where targets are (``form``) and, optionally, when."""

    form: DemandForm
    profile: HourlyProfile | None = None


def parse_demand_spec(text: str) -> DemandRecipe:
    """Parse a ``--demand`` spec (grammar in the module docstring).

    Files are checked to exist here; their content is read when the
    distribution is built, except the profile's, read here.

    Raises
    ------
    InvalidInput
        An unknown form, a bad hotspot count, a missing file.
    """
    form_text, marker, profile_text = text.partition("?profile=")
    profile = None
    if marker:
        if not profile_text:
            raise InvalidInput(f"--demand {text!r}: '?profile=' needs a file of 24 hourly weights")
        profile = read_profile(Path(profile_text))
    return DemandRecipe(_parse_form(form_text), profile)


def _parse_form(text: str) -> DemandForm:
    kind, colon, argument = text.partition(":")
    if text == "uniform":
        return Uniform()
    if kind == "hotspots":
        if not colon:
            return Hotspots()
        if not argument.isdigit() or int(argument) < 1:
            raise InvalidInput(f"--demand hotspots:K needs an integer K >= 1, got {argument!r}")
        return Hotspots(int(argument))
    if kind in ("weights", "buildings") and colon:
        path = Path(argument)
        if not path.is_file():
            raise InvalidInput(f"--demand {text!r}: no file {argument!r}")
        return WeightsFile(path) if kind == "weights" else BuildingsFile(path)
    if text and Path(text).is_file():
        return WeightsFile(Path(text))
    raise InvalidInput(f"--demand must be {SPEC_FORMS}; got {text!r}")


def recipe_from_reference(spec: Mapping[str, Any]) -> DemandRecipe:
    """The recipe of a fleet's stored reference demand (``{"kind": ...}``).

    ``uniform``; ``hotspots`` with ``count`` (default 3) and ``spread``;
    ``weights`` with ``weights`` (edge id -> weight). The centres of hotspots
    are drawn with ``numpy.random.default_rng(spec["seed"])`` by the caller.
    """
    kind = spec["kind"]
    if kind == "uniform":
        return DemandRecipe(Uniform())
    if kind == "hotspots":
        spread = spec.get("spread")
        return DemandRecipe(
            Hotspots(int(spec.get("count", DEFAULT_HOTSPOTS)), None if spread is None else spread)
        )
    if kind == "weights":
        return DemandRecipe(EdgeWeights(dict(spec.get("weights") or {})))
    raise InvalidInput(f"unknown reference demand kind {kind!r}")


def network_demand(
    network: CompiledNetwork, recipe: DemandRecipe | DemandForm, *, rng: np.random.Generator
) -> DemandDistribution[NetPosition]:
    """The distribution of ``recipe`` on ``network`` (``rng`` draws hotspot centres).

    Raises
    ------
    InvalidInput
        A bad file, or no positive weight on the network.
    UnknownEdge
        An in-memory edge weight names an edge that is not in the network.
    """
    from routing_svc.demand import network as demand

    form = recipe.form if isinstance(recipe, DemandRecipe) else recipe
    if isinstance(form, Uniform):
        return demand.uniform_by_length(network)
    if isinstance(form, Hotspots):
        return demand.hotspot_mixture(network, centres=form.count, spread=form.spread, rng=rng)
    if isinstance(form, WeightsFile):
        return demand.from_weights_file(network, form.path)
    if isinstance(form, BuildingsFile):
        return demand.from_buildings_file(network, form.path)
    indexed: dict[int, float] = {}
    for edge_id, weight in form.weights.items():
        index = network.edge_index.get(edge_id)
        if index is None:
            raise UnknownEdge(f"reference demand names unknown edge {edge_id!r}")
        indexed[index] = float(weight)
    if not any(w > 0.0 for w in indexed.values()):
        raise InvalidInput("reference demand weights must give some edge a positive weight")
    return demand.from_edge_weights(network, indexed, name="weights")
