"""Screening of untrusted SUMO network files before sumolib sees them.

An uploaded ``.net.xml`` (or ``.net.xml.gz``) is hostile until proven
otherwise. :func:`read_net_bytes` returns the plain XML bytes of a network
only if

- the (decompressed) content fits in ``max_bytes``; gzip content is inflated
  with a streaming decompressor that stops as soon as the limit is passed, so
  a gzip bomb costs at most ``max_bytes`` of memory
  (:class:`~routing_svc.errors.PayloadTooLarge`);
- the XML stays within the bounds of :mod:`routing_svc.network.xml_limits`
  (attribute values, attributes per element, tags, elements per byte) and
  runs of text are at most :data:`~routing_svc.network.xml_limits.MAX_TEXT_CHARS`
  long (:class:`~routing_svc.errors.XmlLimitExceeded`, naming the limit);
- the XML is well formed, declares no DOCTYPE and no entity (which rules out
  external entities and "billion laughs" expansion), nests no deeper than
  :data:`MAX_DEPTH` elements, and its root element is ``<net>``
  (:class:`~routing_svc.errors.InvalidNetwork` otherwise).

:class:`XmlScreen` does the checks over a stream of chunks: each chunk goes
first through the byte-level :class:`~routing_svc.network.xml_limits.ByteScreen`,
then to the C expat parser with a handful of Python callbacks. Files on disk
(networks named at start-up, and any other XML file read from outside, such
as an OpenStreetMap extract with ``root="osm"``) go through the same screen
with :func:`check_xml_file`. Time and memory are linear in the document:
the parser never holds more than a chunk and one bounded token.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from xml.parsers import expat

from routing_svc.errors import InvalidInput, InvalidNetwork, PayloadTooLarge, XmlLimitExceeded
from routing_svc.network.xml_limits import (
    MAX_MARKUP_BYTES,
    MAX_TEXT_CHARS,
    ByteScreen,
    markup_too_long,
)

__all__ = [
    "GZIP_MAGIC",
    "MAX_DEPTH",
    "XmlScreen",
    "check_net_xml",
    "check_net_xml_file",
    "check_xml_file",
    "plain_xml_chunks",
    "read_net_bytes",
]

GZIP_MAGIC = b"\x1f\x8b"
MAX_DEPTH = 64
"""Deepest nesting of elements."""
_CHUNK = 1 << 18
"""Bytes screened and parsed at a time (256 KiB)."""


def read_net_bytes(data: bytes | bytearray, *, max_bytes: int) -> bytes | bytearray:
    """Return the validated XML bytes of an uploaded SUMO network.

    Parameters
    ----------
    data : bytes or bytearray
        The uploaded file: plain XML or gzip-compressed XML.
    max_bytes : int
        Largest accepted size of the (decompressed) XML, in bytes.

    Returns
    -------
    bytes or bytearray
        The plain (decompressed) XML, safe to write to disk and hand to sumolib:
        ``data`` itself (not a copy) when it was not compressed.

    Raises
    ------
    PayloadTooLarge
        If the content, after decompression, exceeds ``max_bytes``.
    XmlLimitExceeded
        If the XML passes one of the limits of :mod:`~routing_svc.network.xml_limits`
        or :data:`~routing_svc.network.xml_limits.MAX_TEXT_CHARS`.
    InvalidNetwork
        If the gzip stream is corrupt, or the XML is malformed, declares a
        DOCTYPE or an entity, nests too deeply, or its root is not ``<net>``.
    InvalidInput
        If ``max_bytes`` is not positive.
    """
    if max_bytes <= 0:
        raise InvalidInput(f"max_bytes must be positive, got {max_bytes}")
    if data[:2] == GZIP_MAGIC:
        return _gunzip_screened(data, max_bytes=max_bytes)
    if len(data) > max_bytes:
        raise PayloadTooLarge(f"network file larger than {max_bytes} bytes")
    check_net_xml(data)
    return data


def _gunzip_screened(data: bytes | bytearray, *, max_bytes: int) -> bytes:
    """Inflate and screen the gzip stream ``data``, stopping at the first limit passed."""
    screen = XmlScreen(root="net")
    out = bytearray()
    for piece in _inflate(_pieces(data)):
        if len(out) + len(piece) > max_bytes:
            raise PayloadTooLarge(f"decompressed network larger than {max_bytes} bytes")
        screen.feed(piece)
        out += piece
    screen.close()
    return bytes(out)


def _pieces(data: bytes | bytearray) -> Iterator[bytes]:
    """``data`` in pieces of at most ``_CHUNK`` bytes."""
    view = memoryview(data)
    for start in range(0, len(view), _CHUNK):
        yield bytes(view[start : start + _CHUNK])


def _inflate(chunks: Iterable[bytes]) -> Iterator[bytes]:
    """Yield the plain bytes of a gzip stream, at most ``_CHUNK`` bytes at a time.

    A stream of several gzip members (as some tools write) is inflated member
    after member.

    Raises
    ------
    InvalidNetwork
        If the stream is corrupt, truncated, or followed by other data.
    """
    inflater = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
    try:
        for chunk in chunks:
            pending = chunk
            while pending:
                if inflater.eof:
                    if len(pending) >= 2 and pending[:2] != GZIP_MAGIC:
                        raise InvalidNetwork("unexpected data after the gzip stream")
                    inflater = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
                piece = inflater.decompress(pending, _CHUNK)
                pending = inflater.unused_data if inflater.eof else inflater.unconsumed_tail
                if piece:
                    yield piece
        while not inflater.eof:
            piece = inflater.decompress(b"", _CHUNK)
            if not piece:
                break
            yield piece
    except zlib.error as exc:
        raise InvalidNetwork(f"corrupt gzip stream: {exc}") from None
    if not inflater.eof:
        raise InvalidNetwork("truncated gzip stream")


class _Callbacks:
    """Expat callbacks: reject DTDs and entities, bound nesting and runs of text."""

    def __init__(self, root: str) -> None:
        self.expected_root = root
        self.depth = 0
        self.root: str | None = None
        self.text = 0

    def start(self, name: str, _attributes: list[str]) -> None:
        if self.root is None:
            self.root = name
            if name != self.expected_root:
                raise InvalidNetwork(f"root element is <{name}>, expected <{self.expected_root}>")
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise InvalidNetwork(f"XML nested deeper than {MAX_DEPTH} elements")
        self.text = 0

    def end(self, _name: str) -> None:
        self.depth -= 1
        self.text = 0

    def characters(self, data: str) -> None:
        self.text += len(data)
        if self.text > MAX_TEXT_CHARS:
            raise XmlLimitExceeded(
                f"a run of text is longer than {MAX_TEXT_CHARS} characters",
                limit="MAX_TEXT_CHARS",
                maximum=MAX_TEXT_CHARS,
            )

    @staticmethod
    def doctype(*_args: object) -> None:
        raise InvalidNetwork("DOCTYPE declarations are not allowed in a network file")

    @staticmethod
    def entity(*_args: object) -> None:
        raise InvalidNetwork("entity declarations are not allowed in a network file")

    @staticmethod
    def external_entity(*_args: object) -> int:
        raise InvalidNetwork("external entities are not allowed in a network file")


class XmlScreen:
    """All checks on an untrusted XML document, fed in chunks.

    Each chunk passes the byte-level :class:`~routing_svc.network.xml_limits.ByteScreen`
    before expat parses it; after each chunk, the token expat still holds
    unfinished (a tag, comment or processing instruction) may not be longer
    than :data:`~routing_svc.network.xml_limits.MAX_MARKUP_BYTES`.

    Parameters
    ----------
    root : str
        The name the root element must have (``"net"`` for a SUMO network).
    """

    def __init__(self, *, root: str) -> None:
        self.bytes = ByteScreen()
        self.callbacks = _Callbacks(root)
        self.fed = 0
        parser = expat.ParserCreate()
        parser.ordered_attributes = True
        parser.buffer_text = True
        parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
        parser.StartElementHandler = self.callbacks.start
        parser.EndElementHandler = self.callbacks.end
        parser.CharacterDataHandler = self.callbacks.characters
        parser.StartDoctypeDeclHandler = self.callbacks.doctype
        parser.EntityDeclHandler = self.callbacks.entity
        parser.UnparsedEntityDeclHandler = self.callbacks.entity
        parser.NotationDeclHandler = self.callbacks.entity
        parser.ExternalEntityRefHandler = self.callbacks.external_entity
        self.parser = parser

    def feed(self, chunk: bytes) -> None:
        """Screen and parse the next ``chunk`` (at most a few MiB at a time).

        Raises
        ------
        XmlLimitExceeded
            If the document passes a limit.
        InvalidNetwork
            If it is malformed, declares a DOCTYPE or entity, nests too
            deeply or has the wrong root.
        """
        self.bytes.feed(chunk)
        self._parse(chunk, final=False)
        self.fed += len(chunk)
        if self.fed - self.parser.CurrentByteIndex > MAX_MARKUP_BYTES:
            raise markup_too_long()

    def close(self) -> None:
        """Finish the document: it must be complete and hold a root element."""
        self._parse(b"", final=True)
        if self.callbacks.root is None:
            raise InvalidNetwork("the file holds no XML element")

    def _parse(self, chunk: bytes, *, final: bool) -> None:
        try:
            self.parser.Parse(chunk, final)
        except expat.ExpatError as exc:
            raise InvalidNetwork(f"malformed XML: {exc}") from None


def check_net_xml(xml: bytes | bytearray) -> None:
    """Raise unless ``xml`` is a safe, well-formed ``<net>`` document within the limits.

    Parameters
    ----------
    xml : bytes or bytearray
        Plain (not compressed) XML.

    Raises
    ------
    XmlLimitExceeded, InvalidNetwork
        As :meth:`XmlScreen.feed` and :meth:`XmlScreen.close`.
    """
    screen = XmlScreen(root="net")
    for piece in _pieces(xml):
        screen.feed(piece)
    screen.close()


def check_xml_file(path: Path, *, root: str) -> None:
    """Stream an XML file (plain or gzip) from disk through :class:`XmlScreen`.

    Parameters
    ----------
    path : Path
        The file; gzip content is recognised by its magic bytes.
    root : str
        The name its root element must have.
    """
    screen = XmlScreen(root=root)
    for chunk in plain_xml_chunks(path):
        screen.feed(chunk)
    screen.close()


def check_net_xml_file(path: Path) -> None:
    """Stream a ``.net.xml`` or ``.net.xml.gz`` file from disk through the same checks.

    Parameters
    ----------
    path : Path
        The network file; gzip content is recognised by its magic bytes.
    """
    check_xml_file(path, root="net")


def plain_xml_chunks(source: Path | bytes | bytearray) -> Iterator[bytes]:
    """Yield the plain XML of a network file or of its bytes, a chunk at a time.

    Parameters
    ----------
    source : Path, bytes or bytearray
        A ``.net.xml`` or ``.net.xml.gz`` file, or its content; gzip content is
        recognised by its magic bytes and inflated as it is read.

    Raises
    ------
    InvalidNetwork
        If the gzip stream is corrupt or truncated.
    """
    if not isinstance(source, Path):
        pieces = _pieces(source)
        yield from _inflate(pieces) if source[:2] == GZIP_MAGIC else pieces
        return
    with source.open("rb") as raw:
        gzipped = raw.read(2) == GZIP_MAGIC
        raw.seek(0)
        chunks: Iterable[bytes] = iter(lambda: raw.read(_CHUNK), b"")
        yield from _inflate(chunks) if gzipped else chunks
