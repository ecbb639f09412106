"""Atomic file writes: write under a temporary name, then rename onto the target.

The implementation lives in :mod:`rangesim.core.atomic` (so every layer, including the
ones below or beside ``io``, can use it); this module keeps the established import path.
"""
from rangesim.core.atomic import atomic_path, temp_path_for

__all__ = ["atomic_path", "temp_path_for"]
