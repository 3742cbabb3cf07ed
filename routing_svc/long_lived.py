"""Long-lived objects kept out of the cyclic garbage collector's full passes."""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["frozen_heap"]


@contextmanager
def frozen_heap() -> Iterator[None]:
    """Freeze what exists now (networks, fleets, loaded tables) for the block.

    A write loop allocates many short-lived containers, and each full pass of the
    collector would otherwise scan every object the process holds; frozen objects
    are not scanned (``gc.freeze``). They are unfrozen afterwards.
    """
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()
