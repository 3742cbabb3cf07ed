"""The limits of the XML screen, each just under and just over, and real files within them."""

from __future__ import annotations

import gzip
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from routing_svc.errors import InvalidNetwork, XmlLimitExceeded
from routing_svc.network import load_network, read_net_bytes
from routing_svc.network.safe_xml import XmlScreen, check_net_xml_file, check_xml_file
from routing_svc.network.xml_limits import (
    ELEMENT_ALLOWANCE,
    MAX_ATTRIBUTE_BYTES,
    MAX_ATTRIBUTES,
    MAX_MARKUP_BYTES,
    MAX_TEXT_CHARS,
    MIN_BYTES_PER_ELEMENT,
)
from tests.network.conftest import BS3D_NET, DRT_NET, SUMO_HOME

MIB = 1 << 20
SHARED = Path(__file__).resolve().parents[3] / "shared" / "nets"
LIMIT = 80 * MIB


def net(body: bytes) -> bytes:
    """``body`` inside a ``<net>`` root, after a few ordinary elements."""
    head = b'<?xml version="1.0"?>\n<net version="1.9">\n  <location netOffset="0,0"/>\n'
    return head + body + b'\n  <edge id="after" from="a" to="b"/>\n</net>\n'


def long_value(size: int) -> bytes:
    return net(b'  <edge id="e" shape="' + b"1" * size + b'"/>')


def attributes(count: int, *, padding: int = 0) -> bytes:
    pairs = b" ".join(b'a%d="%s"' % (i, b"=" * padding) for i in range(count))
    return net(b"  <edge " + pairs + b"/>")


def text(size: int) -> bytes:
    return net(b"  <edge>" + b"t" * size + b"</edge>")


def elements(count: int) -> bytes:
    return b"<net>" + b"<a/>" * (count - 1) + b"</net>"


def most_elements() -> int:
    """The most elements that :func:`elements` may hold within the element limit."""
    count = ELEMENT_ALLOWANCE
    while count + 1 <= ELEMENT_ALLOWANCE + len(elements(count + 1)) // MIN_BYTES_PER_ELEMENT:
        count += 1
    return count


def long_tag(size: int) -> bytes:
    """A start tag of exactly ``size`` bytes, every value within its own limit."""
    values: list[bytes] = []
    room = size - len(b"<edge/>")
    while room > 0:
        piece = min(room, MAX_ATTRIBUTE_BYTES + len(b' v00=""'))
        values.append(b" v%02d=" % len(values) + b'"' + b"1" * (piece - 7) + b'"')
        room -= piece
    tag = b"<edge" + b"".join(values) + b"/>"
    assert len(tag) == size
    return net(b"  " + tag)


def screen(document: bytes, *, gzipped: bool) -> bytes | bytearray:
    data = gzip.compress(document, compresslevel=1) if gzipped else document
    return read_net_bytes(data, max_bytes=LIMIT)


CASES: dict[str, tuple[Callable[[int], bytes], int, str]] = {
    "attribute_value": (long_value, MAX_ATTRIBUTE_BYTES, "MAX_ATTRIBUTE_BYTES"),
    "attributes": (attributes, MAX_ATTRIBUTES, "MAX_ATTRIBUTES"),
    "text": (text, MAX_TEXT_CHARS, "MAX_TEXT_CHARS"),
    "elements": (elements, most_elements(), "MIN_BYTES_PER_ELEMENT"),
    "start_tag": (long_tag, MAX_MARKUP_BYTES, "MAX_MARKUP_BYTES"),
}


@pytest.mark.parametrize("gzipped", [False, True], ids=["plain", "gzip"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_each_limit_just_under_passes_and_just_over_is_named(case: str, gzipped: bool) -> None:
    make, limit, name = CASES[case]
    fine = make(limit)
    assert screen(fine, gzipped=gzipped) == fine
    with pytest.raises(XmlLimitExceeded) as raised:
        screen(make(limit + 1), gzipped=gzipped)
    assert raised.value.limit == name
    assert str(limit) in raised.value.detail or name == "MIN_BYTES_PER_ELEMENT"


def test_equals_signs_inside_values_are_not_attributes() -> None:
    crowded = attributes(MAX_ATTRIBUTES, padding=3)  # three '=' in every value
    assert read_net_bytes(crowded, max_bytes=MIB) == crowded
    quoted = net(b'  <edge a=\'say "x=1" > ' + b"=" * 200 + b"' b=\"it's\"/>")
    assert read_net_bytes(quoted, max_bytes=MIB) == quoted


def test_long_comment_is_stopped() -> None:
    comment = net(b"<!--" + b"c" * (MAX_MARKUP_BYTES + 2 * MIB) + b"-->")
    with pytest.raises(XmlLimitExceeded) as raised:
        read_net_bytes(comment, max_bytes=LIMIT)
    assert raised.value.limit == "MAX_MARKUP_BYTES"


def test_long_attribute_name_is_stopped() -> None:
    named = net(b"  <edge " + b"n" * (MAX_MARKUP_BYTES + 1) + b'="1"/>')
    with pytest.raises(XmlLimitExceeded) as raised:
        read_net_bytes(named, max_bytes=LIMIT)
    assert raised.value.limit == "MAX_MARKUP_BYTES"


def pieces(data: bytes, size: int) -> Iterator[bytes]:
    for start in range(0, len(data), size):
        yield data[start : start + size]


TRICKY = net(
    b'<!-- a comment with <tags a="1"> and = signs ==== -->\n'
    b"<?pi with <angle> brackets?>\n"
    b'  <edge id=\'e"1\' shape="0,0 1,1" note="a > b, c=d"/>\n'
    b'  <edge id="e2"><![CDATA[ <not a tag> ]]></edge>\n'
    + b'  <lane id="l" index="0" speed="13.89" length="10.00" shape="0,0 10,0"/>\n'
    * 50
)


@pytest.mark.parametrize("size", [1, 7, 64, 4096])
def test_verdict_does_not_depend_on_where_chunks_end(size: int) -> None:
    screen = XmlScreen(root="net")
    for piece in pieces(TRICKY, size):
        screen.feed(piece)
    screen.close()
    crowded = XmlScreen(root="net")
    with pytest.raises(XmlLimitExceeded, match="attributes"):
        for piece in pieces(attributes(MAX_ATTRIBUTES + 1), size):
            crowded.feed(piece)
    over = TRICKY.replace(b' note="', b' big="' + b"x" * (MAX_ATTRIBUTE_BYTES + 1) + b'" note="')
    screen = XmlScreen(root="net")
    with pytest.raises(XmlLimitExceeded, match="attribute value"):
        for piece in pieces(over, max(size, 4096)):
            screen.feed(piece)


@pytest.fixture(scope="module")
def grid_net(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 40 x 40 junction grid (6,240 edges); the benchmark screens a 160 x 160 one."""
    path = tmp_path_factory.mktemp("grid") / "grid40.net.xml"
    subprocess.run(
        [str(SUMO_HOME / "bin" / "netgenerate"), "--grid", "--grid.number=40",
         "--grid.length=100", "--output-file", str(path)],
        check=True, capture_output=True,
    )  # fmt: skip
    return path


REAL = {
    "drt": DRT_NET,
    "bs3d": BS3D_NET,
    "badhersfeld": SHARED / "badhersfeld.net.xml.gz",
    "bologna": SHARED / "bologna.net.xml.gz",
}


@pytest.mark.parametrize("name", sorted(REAL))
def test_real_networks_are_within_the_limits(name: str) -> None:
    check_net_xml_file(REAL[name])
    raw = REAL[name].read_bytes()
    assert read_net_bytes(raw, max_bytes=64 * MIB)[:5] == b"<?xml"


def test_generated_grid_is_within_the_limits(grid_net: Path) -> None:
    check_net_xml_file(grid_net)


def test_openstreetmap_extract_is_within_the_limits() -> None:
    check_xml_file(SHARED / "badhersfeld.osm.xml.gz", root="osm")
    with pytest.raises(InvalidNetwork, match="root element"):
        check_net_xml_file(SHARED / "badhersfeld.osm.xml.gz")


@pytest.mark.parametrize("gzipped", [False, True], ids=["plain", "gzip"])
def test_files_on_disk_get_the_same_limits(tmp_path: Path, gzipped: bool) -> None:
    """The start-up path (``--net``): a file past a limit never reaches sumolib."""
    document = long_value(MAX_ATTRIBUTE_BYTES + 1)
    path = tmp_path / ("big.net.xml.gz" if gzipped else "big.net.xml")
    path.write_bytes(gzip.compress(document) if gzipped else document)
    with pytest.raises(XmlLimitExceeded, match="attribute value"):
        load_network(path, cache_dir=tmp_path)
