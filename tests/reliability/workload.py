"""``fleet_body`` for ``test_fuzzing``, which imports it from here.

Shared helpers live in :mod:`tests.helpers`; import them from there."""

from __future__ import annotations

from tests.helpers import fleet_body

__all__ = ["fleet_body"]
