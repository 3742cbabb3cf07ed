"""Bounds on untrusted XML, checked over the raw bytes before a parser builds anything.

A parser that hands a start tag's attributes to Python builds every name and
value as a string at once: one huge attribute value, or millions of
attributes on one element, costs memory and time out of proportion to the
upload. :class:`ByteScreen` looks at the bytes first, a chunk at a time, and
rejects a document that passes one of these limits
(:class:`~routing_svc.errors.XmlLimitExceeded`, which names the limit):

- :data:`MAX_ATTRIBUTE_BYTES`: the bytes of one attribute value, as written;
- :data:`MAX_ATTRIBUTES`: attributes on one element;
- :data:`MAX_MARKUP_BYTES`: one start tag with all its attributes (end tags,
  comments and processing instructions are held to it by the parser's screen
  where each chunk ends, so one of those is stopped at most a chunk past it);
- :data:`MIN_BYTES_PER_ELEMENT` and :data:`ELEMENT_ALLOWANCE`: the start tags
  read so far may not outnumber ``ELEMENT_ALLOWANCE + bytes / MIN_BYTES_PER_ELEMENT``.

The text limit (:data:`MAX_TEXT_CHARS`) is checked by the parser's screen in
:mod:`routing_svc.network.safe_xml`, which sees text in bounded pieces.

How it stays linear: numpy finds every ``<`` and ``=`` of a chunk, and cuts
the chunk into *regions*, each from one ``<`` to the next. Every attribute of
a well-formed start tag has an ``=``, and no ``<`` can stand inside a tag, so
a region no longer than :data:`_PLAIN_REGION_BYTES` with at most
:data:`MAX_ATTRIBUTES` ``=`` signs is within every limit without a closer
look. Only the other regions are read closely: a region with more ``=`` signs
by one regular expression that matches ``MAX_ATTRIBUTES + 1`` attributes, a
long region (at most a few per mebibyte) attribute by attribute. The start
tag still open at the end of a chunk is carried into the next one; it is
never longer than :data:`MAX_MARKUP_BYTES`. ``<`` inside comments and CDATA
sections is counted as if it began a tag, which only makes the screen
stricter, never looser.
"""

from __future__ import annotations

import re

import numpy as np

from routing_svc.errors import XmlLimitExceeded

__all__ = [
    "ELEMENT_ALLOWANCE",
    "MAX_ATTRIBUTES",
    "MAX_ATTRIBUTE_BYTES",
    "MAX_MARKUP_BYTES",
    "MAX_TEXT_CHARS",
    "MIN_BYTES_PER_ELEMENT",
    "ByteScreen",
    "markup_too_long",
]

MAX_ATTRIBUTE_BYTES = 1 << 20
"""Longest attribute value, in bytes as written in the file (1 MiB).

SUMO's longest attributes are lane and junction shapes and a junction's list
of internal lanes; ``docs/reliability.md`` gives the longest ones measured in
real networks, far below this."""

MAX_ATTRIBUTES = 64
"""Most attributes on one element (SUMO's richest element, ``connection``, has
about 25 possible ones)."""

MAX_MARKUP_BYTES = 4 << 20
"""Longest start tag (with its attributes), end tag, comment or processing
instruction, in bytes (4 MiB)."""

MAX_TEXT_CHARS = 1 << 16
"""Longest run of character data between two tags, in characters (64 Ki);
SUMO writes only indentation there."""

MIN_BYTES_PER_ELEMENT = 16
"""Fewest bytes per element that a document may average: a file may hold at
most ``ELEMENT_ALLOWANCE + size / MIN_BYTES_PER_ELEMENT`` elements, counted as
the bytes are read."""

ELEMENT_ALLOWANCE = 4096
"""Elements a document may hold beyond its size's share (for small files)."""

_PLAIN_REGION_BYTES = 1 << 16
"""Regions up to this long need no close look (no longer than any limit)."""

_LT, _EQ = ord("<"), ord("=")
_NAME_START = np.zeros(256, dtype=np.bool_)
_NAME_START[[ord(c) for c in "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz_:"]] = True
_NAME_START[0x80:] = True
_TAG_NAME = re.compile(rb"<[^\s/>]*+")
_NEXT_ATTRIBUTE = re.compile(rb"\s*+(?:(/?>)|[^\s=/>]++\s*+=\s*+([\"']))")
_TOO_MANY_ATTRIBUTES = re.compile(
    rb"<[^\s/>]++(?:\s++[^\s=/>]++\s*+=\s*+(?:\"[^\"]*+\"|'[^']*+')){%d}" % (MAX_ATTRIBUTES + 1)
)


def too_many_attributes() -> XmlLimitExceeded:
    """The error for an element with more than :data:`MAX_ATTRIBUTES` attributes."""
    return XmlLimitExceeded(
        f"an element has more than {MAX_ATTRIBUTES} attributes",
        limit="MAX_ATTRIBUTES",
        maximum=MAX_ATTRIBUTES,
    )


def markup_too_long() -> XmlLimitExceeded:
    """The error for a tag, comment or processing instruction over :data:`MAX_MARKUP_BYTES`."""
    return XmlLimitExceeded(
        f"a tag, comment or processing instruction is longer than {MAX_MARKUP_BYTES} bytes",
        limit="MAX_MARKUP_BYTES",
        maximum=MAX_MARKUP_BYTES,
    )


def _scan_start_tag(buf: bytes, start: int, stop: int) -> int:
    """Read the start tag at ``buf[start]`` attribute by attribute, up to ``stop``.

    Returns
    -------
    int
        The index just after the tag's ``>``, or -1 if the tag does not end
        before ``stop`` (it goes on in the next chunk, or it is malformed,
        which the parser reports).

    Raises
    ------
    XmlLimitExceeded
        If the tag passes a limit before ``stop``.
    """
    name = _TAG_NAME.match(buf, start, stop)
    pos = name.end() if name is not None else start + 1
    attributes = 0
    while True:
        found = _NEXT_ATTRIBUTE.match(buf, pos, stop)
        if found is None:
            break
        if found.group(1) is not None:
            if found.end() - start > MAX_MARKUP_BYTES:
                raise markup_too_long()
            return found.end()
        attributes += 1
        if attributes > MAX_ATTRIBUTES:
            raise too_many_attributes()
        opened = found.end()
        closed = buf.find(found.group(2), opened, stop)
        if (closed if closed >= 0 else stop) - opened > MAX_ATTRIBUTE_BYTES:
            raise XmlLimitExceeded(
                f"an attribute value is longer than {MAX_ATTRIBUTE_BYTES} bytes",
                limit="MAX_ATTRIBUTE_BYTES",
                maximum=MAX_ATTRIBUTE_BYTES,
            )
        if closed < 0:
            break
        pos = closed + 1
    if stop - start > MAX_MARKUP_BYTES:
        raise markup_too_long()
    return -1


class ByteScreen:
    """Feed the bytes of a document in chunks; raises at the first limit passed.

    The screen keeps the start tag still open at the end of a chunk (at most
    :data:`MAX_MARKUP_BYTES`) and three counters; its work per chunk is a few
    numpy passes over the chunk.
    """

    def __init__(self) -> None:
        self.carry = b""
        self.bytes_read = 0
        self.elements = 0

    def feed(self, chunk: bytes) -> None:
        """Screen the next ``chunk`` of the document.

        Raises
        ------
        XmlLimitExceeded
            If the bytes read so far pass one of the module's limits.
        """
        self.bytes_read += len(chunk)
        buf = self.carry + chunk if self.carry else chunk
        self.carry = b""
        data = np.frombuffer(buf, dtype=np.uint8)
        starts = np.flatnonzero(data == _LT)
        if starts.size == 0:
            return
        ends = np.append(starts[1:], len(buf))
        after = starts + 1
        opens_tag = np.zeros(starts.size, dtype=np.bool_)
        inside = after < len(buf)
        opens_tag[inside] = _NAME_START[data[after[inside]]]
        equals = np.flatnonzero(data == _EQ)
        n_equals = np.searchsorted(equals, ends) - np.searchsorted(equals, starts)
        crowded = opens_tag & (n_equals > MAX_ATTRIBUTES)
        crowded[-1] = False
        for i in np.flatnonzero(crowded):
            if _TOO_MANY_ATTRIBUTES.match(buf, int(starts[i]), int(ends[i])):
                raise too_many_attributes()
        lengthy = opens_tag & (ends - starts > _PLAIN_REGION_BYTES)
        lengthy[-1] = False
        for i in np.flatnonzero(lengthy):
            _scan_start_tag(buf, int(starts[i]), int(ends[i]))
        counted = int(np.count_nonzero(opens_tag))
        last = int(starts[-1])
        if not inside[-1] or (opens_tag[-1] and _scan_start_tag(buf, last, len(buf)) < 0):
            self.carry = buf[last:]
            counted -= int(opens_tag[-1])
        self.elements += counted
        budget = ELEMENT_ALLOWANCE + self.bytes_read // MIN_BYTES_PER_ELEMENT
        if self.elements > budget:
            raise XmlLimitExceeded(
                f"{self.elements} elements in the first {self.bytes_read} bytes: more than "
                f"{ELEMENT_ALLOWANCE} + 1 per {MIN_BYTES_PER_ELEMENT} bytes",
                limit="MIN_BYTES_PER_ELEMENT",
                maximum=budget,
            )
