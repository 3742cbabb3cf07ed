"""``frozen_heap``: what exists at entry is frozen for the block and unfrozen after."""

from __future__ import annotations

import gc

import pytest

from routing_svc.long_lived import frozen_heap


def test_the_heap_is_frozen_inside_and_unfrozen_after_even_on_error() -> None:
    gc.unfreeze()
    kept = [{"held": i} for i in range(100)]
    with frozen_heap():
        assert gc.get_freeze_count() >= len(kept)
    assert gc.get_freeze_count() == 0
    with pytest.raises(RuntimeError), frozen_heap():
        assert gc.get_freeze_count() > 0
        raise RuntimeError("inside")
    assert gc.get_freeze_count() == 0
