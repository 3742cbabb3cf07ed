"""The on-disk cache of compiled networks."""

from __future__ import annotations

import gzip
import hashlib
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from routing_svc.errors import InvalidNetwork, UnknownNetwork
from routing_svc.network import CompiledNetwork, default_cache_dir, load_network
from routing_svc.network.identity import network_sha256
from tests.network.conftest import DRT_NET, NetCase


def assert_same_network(a: CompiledNetwork, b: CompiledNetwork) -> None:
    assert a.edge_ids == b.edge_ids
    assert a.junction_ids == b.junction_ids
    assert a.edge_index == b.edge_index
    assert (a.vclass, a.source_sha256, a.bounds) == (b.vclass, b.source_sha256, b.bounds)
    assert a.projection == b.projection
    assert a.reduction == b.reduction
    arrays_a, arrays_b = a.arrays(), b.arrays()
    assert arrays_a.keys() == arrays_b.keys()
    for name, array in arrays_a.items():
        assert array.dtype == arrays_b[name].dtype, name
        np.testing.assert_array_equal(array, arrays_b[name], err_msg=name)


def read_npz(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as stored:
        return dict(stored)


def cache_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix in {".npz", ".json"})


def test_cached_load_equals_fresh_compile(oneway_path: Path, tmp_path: Path) -> None:
    fresh = load_network(oneway_path, cache_dir=tmp_path)
    assert len(cache_files(tmp_path)) == 2
    cached = load_network(oneway_path, cache_dir=tmp_path)
    assert cached is not fresh
    assert_same_network(fresh, cached)


def test_cached_load_does_not_use_sumolib(oneway_path: Path, tmp_path: Path) -> None:
    load_network(oneway_path, cache_dir=tmp_path)
    other = tmp_path / "other.net.xml"
    other.write_bytes(oneway_path.read_bytes() + b"<!-- another file -->\n")
    script = textwrap.dedent(
        f"""
        import sys
        sys.modules["sumolib"] = None  # any import of sumolib now fails
        from pathlib import Path
        from routing_svc.network import load_network
        net = load_network({str(oneway_path)!r}, cache_dir=Path({str(tmp_path)!r}))
        print(net.n_edges)
        try:
            load_network({str(other)!r}, cache_dir=Path({str(tmp_path)!r}))
        except ImportError:
            print("compiling needs sumolib")
        """
    )
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    n_edges = load_network(oneway_path, cache_dir=tmp_path).n_edges
    assert result.stdout.split("\n")[:2] == [str(n_edges), "compiling needs sumolib"]


def test_key_depends_on_content_and_vehicle_class(oneway_path: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    load_network(oneway_path, cache_dir=cache)
    load_network(oneway_path, vclass="truck", cache_dir=cache)
    assert len(cache_files(cache)) == 4
    changed = tmp_path / "changed.net.xml"
    changed.write_bytes(oneway_path.read_bytes() + b"\n")
    network = load_network(changed, cache_dir=cache)
    assert len(cache_files(cache)) == 6
    assert network.source_sha256 != load_network(oneway_path, cache_dir=cache).source_sha256


@pytest.mark.parametrize("damage", ["truncated-npz", "garbage-json", "wrong-array", "bad-graph"])
def test_damaged_cache_is_rebuilt(oneway_path: Path, tmp_path: Path, damage: str) -> None:
    fresh = load_network(oneway_path, cache_dir=tmp_path)
    npz = next(tmp_path.glob("*.npz"))
    meta = npz.with_suffix(".json")
    if damage == "truncated-npz":
        npz.write_bytes(npz.read_bytes()[:100])
    elif damage == "garbage-json":
        meta.write_text("{not json")
    elif damage == "wrong-array":
        arrays = read_npz(npz)
        arrays["length"] = arrays["length"].astype(np.float32)
        np.savez(npz, **arrays)  # type: ignore[arg-type]
    else:
        arrays = read_npz(npz)
        arrays["fwd_indices"] = np.full_like(arrays["fwd_indices"], 10**6)
        np.savez(npz, **arrays)  # type: ignore[arg-type]
    assert_same_network(fresh, load_network(oneway_path, cache_dir=tmp_path))
    assert_same_network(fresh, load_network(oneway_path, cache_dir=tmp_path))


def test_metadata_is_plain_json(oneway_path: Path, tmp_path: Path) -> None:
    network = load_network(oneway_path, cache_dir=tmp_path)
    meta = json.loads(next(tmp_path.glob("*.json")).read_text())
    assert meta["edge_ids"] == list(network.edge_ids)
    assert meta["reduction"]["dropped_edges"] == network.reduction.dropped_edges
    with np.load(next(tmp_path.glob("*.npz")), allow_pickle=False) as stored:
        assert all(stored[name].dtype != object for name in stored.files)


def test_gzipped_network_compiles_like_the_plain_file(drt_case: NetCase, tmp_path: Path) -> None:
    data = DRT_NET.read_bytes()
    packed = tmp_path / "osm.net.xml.gz"  # three gzip members, as some tools write
    packed.write_bytes(
        b"".join(gzip.compress(data[i : i + 2_000_001]) for i in range(0, len(data), 2_000_001))
    )
    network = load_network(packed, cache_dir=tmp_path / "cache")
    plain = drt_case.network
    assert network.edge_ids == plain.edge_ids
    for name, array in plain.arrays().items():
        np.testing.assert_array_equal(network.arrays()[name], array, err_msg=name)


def test_cache_dir_comes_from_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ROUTING_SVC_CACHE", str(tmp_path / "here"))
    assert default_cache_dir() == tmp_path / "here"
    monkeypatch.delenv("ROUTING_SVC_CACHE")
    assert default_cache_dir() == Path.home() / ".cache" / "routing_svc"


def test_missing_file_is_an_unknown_network(tmp_path: Path) -> None:
    with pytest.raises(UnknownNetwork):
        load_network(tmp_path / "absent.net.xml", cache_dir=tmp_path)


def test_malformed_file_is_an_invalid_network(tmp_path: Path) -> None:
    path = tmp_path / "broken.net.xml"
    path.write_text('<net version="1.9"><edge id="a" from="x"')
    with pytest.raises(InvalidNetwork, match="malformed"):
        load_network(path, cache_dir=tmp_path)
    assert not any(tmp_path.glob("*.npz"))


def test_a_file_and_its_gzip_are_one_network(oneway_path: Path, tmp_path: Path) -> None:
    plain = oneway_path.read_bytes()
    packed = tmp_path / "oneway.net.xml.gz"
    packed.write_bytes(gzip.compress(plain))
    identity = hashlib.sha256(plain).hexdigest()
    assert network_sha256(oneway_path) == network_sha256(packed) == identity
    assert network_sha256(plain) == network_sha256(gzip.compress(plain)) == identity
    cache = tmp_path / "cache"
    first = load_network(packed, cache_dir=cache)
    assert load_network(oneway_path, cache_dir=cache).source_sha256 == identity
    assert len(cache_files(cache)) == 2  # one compiled entry for both forms
    assert first.source_sha256 == identity
