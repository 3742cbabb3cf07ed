"""Screening of uploaded network files: size limits, gzip bombs, hostile XML."""

from __future__ import annotations

import gzip
import tracemalloc
import zlib
from collections.abc import Callable
from pathlib import Path

import pytest

from routing_svc.errors import InvalidInput, InvalidNetwork, PayloadTooLarge
from routing_svc.network import load_network, read_net_bytes
from routing_svc.network.safe_xml import MAX_DEPTH
from tests.network.conftest import DRT_NET

MIB = 1 << 20
SMALL_NET = b'<?xml version="1.0"?>\n<!-- a comment -->\n<net version="1.9"><edge id="a"/></net>'


def peak_extra_memory(action: Callable[[], object]) -> int:
    """Peak bytes allocated by Python while ``action`` runs (it is expected to raise)."""
    tracemalloc.start()
    try:
        action()
    except Exception:
        pass
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return peak


def gzip_of_spaces(size: int) -> bytes:
    """A gzip stream that inflates to ``size`` bytes of spaces (a compression bomb)."""
    packer = zlib.compressobj(6, zlib.DEFLATED, 16 + zlib.MAX_WBITS)
    block = b" " * MIB
    parts = [packer.compress(block) for _ in range(size // MIB)]
    return b"".join(parts) + packer.flush()


def test_plain_network_passes_unchanged() -> None:
    data = DRT_NET.read_bytes()
    assert read_net_bytes(data, max_bytes=len(data)) == data


def test_gzipped_network_is_inflated() -> None:
    data = DRT_NET.read_bytes()
    assert read_net_bytes(gzip.compress(data), max_bytes=len(data)) == data


def test_multi_member_gzip_is_inflated_whole() -> None:
    data = DRT_NET.read_bytes()
    cut = len(data) // 3
    members = gzip.compress(data[:cut]) + gzip.compress(b"") + gzip.compress(data[cut:])
    assert read_net_bytes(members, max_bytes=len(data)) == data


def test_plain_file_over_the_limit_is_too_large() -> None:
    with pytest.raises(PayloadTooLarge):
        read_net_bytes(SMALL_NET, max_bytes=len(SMALL_NET) - 1)


def test_gzip_bomb_stops_at_the_limit() -> None:
    bomb = gzip_of_spaces(256 * MIB)  # 256 MiB of spaces in about 256 kB
    assert len(bomb) < MIB // 2

    def inflate() -> None:
        with pytest.raises(PayloadTooLarge):
            read_net_bytes(bomb, max_bytes=8 * MIB)

    assert peak_extra_memory(inflate) < 40 * MIB


def test_billion_laughs_is_rejected_cheaply() -> None:
    entities = "".join(f'<!ENTITY l{i} "{("&l" + str(i - 1) + ";") * 10}">' for i in range(1, 10))
    body = f'<!DOCTYPE net [<!ENTITY l0 "ha">{entities}]><net>&l9;</net>'.encode()
    with pytest.raises(InvalidNetwork, match="DOCTYPE"):
        read_net_bytes(body, max_bytes=MIB)
    padded = body.replace(b"<net>", b"<net>" + b" " * (10 * MIB))
    assert peak_extra_memory(lambda: read_net_bytes(padded, max_bytes=20 * MIB)) < 100 * MIB


@pytest.mark.parametrize(
    "document",
    [
        b'<!DOCTYPE net SYSTEM "file:///etc/passwd"><net/>',
        b'<!DOCTYPE net [<!ENTITY x SYSTEM "file:///etc/passwd">]><net>&x;</net>',
        b'<!DOCTYPE net [<!ENTITY % p SYSTEM "http://example.invalid/p.dtd"> %p;]><net/>',
        b"<!DOCTYPE net><net/>",
    ],
    ids=["external-dtd", "external-entity", "parameter-entity", "bare-doctype"],
)
def test_doctype_and_entities_are_rejected(document: bytes) -> None:
    with pytest.raises(InvalidNetwork, match=r"DOCTYPE|entit"):
        read_net_bytes(document, max_bytes=MIB)


def test_deep_nesting_is_rejected() -> None:
    deep = b"<net>" + (b"<a>" + b" " * 13) * (10 * MIB // 16)
    with pytest.raises(InvalidNetwork, match="nested deeper"):
        read_net_bytes(deep, max_bytes=20 * MIB)
    fine = b"<net>" + b"<a>" * (MAX_DEPTH - 1) + b"</a>" * (MAX_DEPTH - 1) + b"</net>"
    assert read_net_bytes(fine, max_bytes=MIB) == fine


def test_ten_megabytes_of_small_elements_pass() -> None:
    many = b"<net>" + (b"<a/>" + b" " * 12) * (10 * MIB // 16) + b"</net>"
    assert read_net_bytes(many, max_bytes=11 * MIB) == many


@pytest.mark.parametrize(
    ("document", "message"),
    [
        (b"", "malformed|no XML"),
        (b"<net><edge></net>", "malformed"),
        (b"\x00\x01binary", "malformed"),
        (b"<net/><net/>", "malformed"),
        (b"<routes/>", "root element"),
        (b"<?xml version='1.0'?>", "malformed|no XML"),
    ],
)
def test_malformed_or_foreign_xml_is_rejected(document: bytes, message: str) -> None:
    with pytest.raises(InvalidNetwork, match=message):
        read_net_bytes(document, max_bytes=MIB)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (gzip.compress(SMALL_NET)[:-9], "truncated"),
        (gzip.compress(SMALL_NET) + b"junk", "after the gzip stream"),
        (b"\x1f\x8b" + b"\x00" * 30, "corrupt"),
    ],
    ids=["truncated", "trailing", "corrupt"],
)
def test_broken_gzip_is_rejected(data: bytes, message: str) -> None:
    with pytest.raises(InvalidNetwork, match=message):
        read_net_bytes(data, max_bytes=MIB)


def test_limit_must_be_positive() -> None:
    with pytest.raises(InvalidInput):
        read_net_bytes(SMALL_NET, max_bytes=0)


def test_hostile_file_on_disk_never_reaches_sumolib(tmp_path: Path) -> None:
    path = tmp_path / "laughs.net.xml"
    path.write_bytes(b'<!DOCTYPE net [<!ENTITY a "aaaa">]><net>&a;</net>')
    with pytest.raises(InvalidNetwork, match="DOCTYPE"):
        load_network(path, cache_dir=tmp_path)
    packed = tmp_path / "deep.net.xml.gz"
    packed.write_bytes(gzip.compress(b"<net>" + b"<a>" * 1000))
    with pytest.raises(InvalidNetwork, match="nested deeper"):
        load_network(packed, cache_dir=tmp_path)
