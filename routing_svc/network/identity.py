"""The identity of a road network: one hash of its content, however it arrives.

A network named at start-up, uploaded as ``.net.xml`` or as ``.net.xml.gz``,
or added by the co-simulation's client is the same network when its plain
(decompressed) XML is the same: :func:`network_sha256` is the SHA-256 of that
XML, and every path that registers, compares or caches a network calls it.

:func:`file_bytes_sha256` is the identity that start-up networks were stored
under before (the SHA-256 of the file's bytes, for a ``.gz`` file the
compressed bytes); it serves only to recognise such stored hashes.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from routing_svc.network.safe_xml import plain_xml_chunks

__all__ = ["file_bytes_sha256", "network_sha256"]


def network_sha256(source: Path | bytes | bytearray) -> str:
    """SHA-256 (hex) of a network's plain XML.

    Parameters
    ----------
    source : Path or bytes
        A ``.net.xml`` or ``.net.xml.gz`` file, or its content (plain or gzip).

    Returns
    -------
    str
        The same digest for a file, its gzip-compressed form and its bytes.

    Raises
    ------
    InvalidNetwork
        If gzip content is corrupt or truncated.
    """
    digest = hashlib.sha256()
    for chunk in plain_xml_chunks(source):
        digest.update(chunk)
    return digest.hexdigest()


def file_bytes_sha256(path: Path) -> str:
    """SHA-256 (hex) of a file's bytes as stored: the former start-up identity.

    Parameters
    ----------
    path : Path
        A network file.
    """
    with path.open("rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()
