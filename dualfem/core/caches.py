"""Process-wide caches that can be dropped on demand (memory between unrelated runs, cold timings).

Any layer that keeps derived data across calls (the factorization cache of
:mod:`dualfem.numerics.linalg`, a problem's delta-free assembly) registers a function that empties
its cache; :func:`clear_all` calls them all (``dualfem.numerics.linalg.clear_cache`` does).
"""
from __future__ import annotations

from collections.abc import Callable

_CLEARERS: list[Callable[[], None]] = []


def register(clear: Callable[[], None]) -> Callable[[], None]:
    """Register a function that empties one cache (usable as a decorator); returns it."""
    if clear not in _CLEARERS:
        _CLEARERS.append(clear)
    return clear


def clear_all() -> None:
    """Empty every registered cache."""
    for clear in list(_CLEARERS):
        clear()
