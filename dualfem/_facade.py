"""Helpers of the stable facade ``dualfem/*.py`` (docs/plugins.md); not a plugin API itself.

Until 0.1 the facade modules were ``from <core module> import *`` without ``__all__``, so each also
re-exported whatever its core module had imported (``dualfem.problem.QP``, ``dualfem.qp.InputError``,
...). Each facade module now names its contract in ``__all__``; :func:`moved` keeps those accidental
re-exports readable for one release, with a DeprecationWarning naming the path to use instead.
"""
from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable
from typing import Any


def moved(module: str, names: dict[str, str]) -> Callable[[str], Any]:
    """A module-level ``__getattr__`` for facade module ``module``: ``names`` maps each deprecated
    attribute to the module it is imported from now (a stable path where one exists); reading one
    warns (DeprecationWarning, at the reader's line) and returns it; any other name is an
    AttributeError, as for a module without ``__getattr__``."""
    def __getattr__(name: str) -> Any:
        target = names.get(name)
        if target is None:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        warnings.warn(f"{module}.{name} is deprecated (not part of {module}'s API; removed in the next "
                      f"release): import it from {target}", DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module(target), name)
    return __getattr__
