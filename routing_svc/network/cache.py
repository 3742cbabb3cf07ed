"""Load a SUMO network, compiling it once and caching the result on disk.

A compiled network is stored as two files in the cache directory, named by a
key that hashes the network's identity (the SHA-256 of its plain XML, see
:mod:`routing_svc.network.identity`: a file and its ``.gz`` share one entry),
the vehicle class and the compile-format version: ``<key>.npz`` holds the arrays (``numpy.savez``,
loaded with ``allow_pickle=False``) and ``<key>.json`` the ids and the rest.
Both are written to temporary files and renamed into place, so concurrent
loaders never see half a file. A cached load does not import sumolib.

The cache directory is ``$ROUTING_SVC_CACHE`` if set, else
``~/.cache/routing_svc``.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from routing_svc.errors import InvalidNetwork, UnknownNetwork
from routing_svc.network.compile import CompiledNetwork, NetworkReduction, compile_network
from routing_svc.network.identity import network_sha256
from routing_svc.network.projection import GeoProjection
from routing_svc.paths import cache_root

__all__ = ["COMPILE_FORMAT", "default_cache_dir", "load_network"]

COMPILE_FORMAT = 3
"""The compiler's version: a change to what it makes of a file, or to which files it refuses,
raises it, so that no cached result outlives it."""

_DTYPES = {
    "length": np.float64,
    "speed": np.float64,
    "edge_from": np.int32,
    "edge_to": np.int32,
    "fwd_indptr": np.int32,
    "fwd_indices": np.int32,
    "rev_indptr": np.int32,
    "rev_indices": np.int32,
    "shape_xy": np.float64,
    "shape_offsets": np.int32,
}


def default_cache_dir() -> Path:
    """:func:`routing_svc.paths.cache_root`: ``$ROUTING_SVC_CACHE``, or ``~/.cache/routing_svc``."""
    return cache_root()


def _cache_key(source_sha256: str, vclass: str) -> str:
    text = f"{source_sha256}\n{vclass}\n{COMPILE_FORMAT}"
    return hashlib.sha256(text.encode()).hexdigest()


def load_network(
    path: str | Path, *, vclass: str = "passenger", cache_dir: Path | None = None
) -> CompiledNetwork:
    """The compiled edge graph of a SUMO network, from the cache when possible.

    Parameters
    ----------
    path : str or Path
        A ``.net.xml`` or ``.net.xml.gz`` file.
    vclass : str
        SUMO vehicle class whose permissions apply (default ``"passenger"``).
    cache_dir : Path, optional
        Where compiled networks are kept (default: :func:`default_cache_dir`).

    Returns
    -------
    CompiledNetwork
        The largest strongly connected part of the network for ``vclass``.

    Raises
    ------
    UnknownNetwork
        If ``path`` is not a readable file.
    InvalidNetwork
        If the file is hostile, malformed, has no usable edge or no loop of them.
    InvalidInput
        If ``vclass`` is not a SUMO vehicle class.
    """
    source = Path(path)
    if not source.is_file():
        raise UnknownNetwork(f"no network file at {source}")
    digest = network_sha256(source)
    directory = cache_dir if cache_dir is not None else default_cache_dir()
    stem = directory / _cache_key(digest, vclass)
    cached = _read_cache(stem, digest, vclass)
    if cached is not None:
        return cached
    network = compile_network(source, vclass=vclass, source_sha256=digest)
    _write_cache(stem, network)
    return network


def _metadata(network: CompiledNetwork) -> dict[str, Any]:
    projection = network.projection
    return {
        "format": COMPILE_FORMAT,
        "vclass": network.vclass,
        "source_sha256": network.source_sha256,
        "edge_ids": list(network.edge_ids),
        "junction_ids": list(network.junction_ids),
        "bounds": list(network.bounds),
        "projection": None
        if projection is None
        else {"proj": projection.proj, "offset": [projection.offset_x, projection.offset_y]},
        "reduction": {
            "usable_edges": network.reduction.usable_edges,
            "kept_edges": network.reduction.kept_edges,
            "dropped_edges": network.reduction.dropped_edges,
            "components": network.reduction.components,
        },
    }


def _atomic_write(target: Path, write: Any) -> None:
    handle, temporary = tempfile.mkstemp(dir=target.parent, prefix=target.name, suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as f:
            write(f)
        os.chmod(temporary, 0o644)
        os.replace(temporary, target)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def _save_arrays(network: CompiledNetwork) -> Any:
    arrays: dict[str, Any] = network.arrays()
    return lambda f: np.savez(f, **arrays)


def _write_cache(stem: Path, network: CompiledNetwork) -> None:
    """Store ``network``; a cache that cannot be written is skipped (the load still works)."""
    try:
        stem.parent.mkdir(parents=True, exist_ok=True)
        _atomic_write(stem.with_suffix(".npz"), _save_arrays(network))
        text = json.dumps(_metadata(network), separators=(",", ":")).encode()
        _atomic_write(stem.with_suffix(".json"), lambda f: f.write(text))
    except OSError:
        return


def _read_cache(stem: Path, digest: str, vclass: str) -> CompiledNetwork | None:
    """The cached network, or ``None`` when absent, stale or damaged."""
    try:
        meta = json.loads(stem.with_suffix(".json").read_bytes())
        with (
            stem.with_suffix(".npz").open("rb") as f,
            np.load(f, allow_pickle=False) as stored,
        ):
            arrays = {name: stored[name] for name in _DTYPES}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    try:
        if (meta["format"], meta["source_sha256"], meta["vclass"]) != (
            COMPILE_FORMAT,
            digest,
            vclass,
        ):
            return None
        if any(arrays[name].dtype != dtype for name, dtype in _DTYPES.items()):
            return None
        projection = meta["projection"]
        return CompiledNetwork(
            vclass=vclass,
            source_sha256=digest,
            edge_ids=tuple(meta["edge_ids"]),
            junction_ids=tuple(meta["junction_ids"]),
            bounds=tuple(float(v) for v in meta["bounds"]),  # type: ignore[arg-type]
            projection=None
            if projection is None
            else GeoProjection.parse(projection["proj"], tuple(projection["offset"])),
            reduction=NetworkReduction(**meta["reduction"]),
            **arrays,
        )
    except (KeyError, TypeError, ValueError, InvalidNetwork):
        return None
