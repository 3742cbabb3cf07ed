"""Where routing_svc keeps what it derives: one user cache folder.

``$ROUTING_SVC_CACHE``, or ``~/.cache/routing_svc``: compiled networks, generated networks
(``nets/``) and numba's compiled kernels (``numba/``). Nothing is written beside the
installed sources, so a read-only install works and an uninstall leaves nothing behind.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_root", "use_numba_cache"]


def cache_root() -> Path:
    """``$ROUTING_SVC_CACHE``, or ``~/.cache/routing_svc``."""
    configured = os.environ.get("ROUTING_SVC_CACHE")
    return Path(configured) if configured else Path.home() / ".cache" / "routing_svc"


def use_numba_cache() -> None:
    """Point numba's cache locator at ``cache_root() / "numba"`` (``NUMBA_CACHE_DIR``),
    unless the environment already chose a folder. Numba reads it when it is first imported,
    so the package runs this before any module that compiles."""
    os.environ.setdefault("NUMBA_CACHE_DIR", str(cache_root() / "numba"))
