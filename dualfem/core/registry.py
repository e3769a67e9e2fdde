"""Registries of solver and problem plugins.

Every plugin, built-in or third-party, is found through the entry-point groups ``dualfem.solvers``
and ``dualfem.problems``. An entry point names a plugin class, a module whose import registers its
plugins (``@register_solver``), or a package of such modules (every module not starting with ``_``
is imported): dualfem's own ``pyproject.toml`` declares its packages ``dualfem.solvers`` and
``dualfem.problems`` (the repository's folders ``solvers/`` and ``problems/``) that way, so the
core imports no plugin by name. Built-in plugins (those of the ``dualfem`` distribution) are
loaded first and their names are reserved: a third-party plugin registering an existing built-in
name is refused (listed by :func:`entry_point_errors`, naming both), never silently replacing it.
Registration happens on first use, so importing dualfem stays cheap and a plugin whose optional
dependency is missing is still listed.
"""
from __future__ import annotations

import importlib
import pkgutil
import types
from importlib.metadata import entry_points
from typing import TYPE_CHECKING

from dualfem.core.errors import InputError

if TYPE_CHECKING:  # pragma: no cover
    from dualfem.core.problem import Problem
    from dualfem.core.solver import Solver

_SOLVERS: dict[str, type[Solver]] = {}
_PROBLEMS: dict[str, type[Problem]] = {}
#: names registered by dualfem's own plugins (reserved once the built-ins are loaded)
_BUILTIN: dict[str, set[str]] = {"solver": set(), "problem": set()}
_LOADED = False
_LOADING_BUILTIN = False
_ENTRY_POINT_ERRORS: list[str] = []
#: the distribution whose plugins are the built-ins
DISTRIBUTION = "dualfem"


def _register(kind: str, reg: dict, cls):
    if not isinstance(getattr(cls, "name", None), str) or not cls.name:
        raise InputError(f"{kind} plugin {cls.__module__}.{cls.__qualname__} has no name (a non-empty string)")
    if kind == "solver":
        from dualfem.core.solver import check_declared

        check_declared(cls)           # tolerance in (0, 1), exact a bool: else the plugin is refused
    old = reg.get(cls.name)
    if _LOADING_BUILTIN:
        _BUILTIN[kind].add(cls.name)
    elif cls.name in _BUILTIN[kind] and old is not None and old is not cls:
        raise InputError(f"{kind} plugin {cls.__module__}.{cls.__qualname__} may not take the name {cls.name!r} "
                         f"of the built-in {old.__module__}.{old.__qualname__}: choose another name")
    reg[cls.name] = cls
    return cls


def register_solver(cls: type[Solver]) -> type[Solver]:
    """Class decorator: add a solver plugin to the registry under ``cls.name`` (a built-in name is refused)."""
    return _register("solver", _SOLVERS, cls)


def register_problem(cls: type[Problem]) -> type[Problem]:
    """Class decorator: add a problem plugin to the registry under ``cls.name`` (a built-in name is refused)."""
    return _register("problem", _PROBLEMS, cls)


def _load_entry_point(obj, reg) -> None:
    """A class is registered; a module registered its plugins when imported; a package's modules are imported."""
    if isinstance(obj, types.ModuleType):
        if hasattr(obj, "__path__"):
            for info in pkgutil.iter_modules(obj.__path__):
                if not info.name.startswith("_"):
                    importlib.import_module(f"{obj.__name__}.{info.name}")
    else:
        reg(obj)


def _load() -> None:
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    from dualfem.core.quiet import plugin_output

    groups = (("dualfem.solvers", register_solver), ("dualfem.problems", register_problem))
    with plugin_output():                   # a plugin printing at import time must not corrupt --json
        _load_groups(groups)
    if not _BUILTIN["solver"]:
        raise RuntimeError("dualfem's built-in plugins were not found through their entry points: "
                           "install dualfem (pip install -e .) so that its entry points exist")


def _load_groups(groups) -> None:
    global _LOADING_BUILTIN
    for builtin in (True, False):           # dualfem's own plugins first: their names are reserved
        for group, reg in groups:
            for ep in entry_points(group=group):
                dist = getattr(ep, "dist", None)
                if (dist is not None and dist.name == DISTRIBUTION) != builtin:
                    continue
                _LOADING_BUILTIN = builtin
                try:
                    _load_entry_point(ep.load(), reg)
                except BaseException as exc:  # a broken third-party plugin (even SystemExit) must not break dualfem
                    if builtin or type(exc) is KeyboardInterrupt:    # a real Ctrl-C still stops
                        raise
                    _ENTRY_POINT_ERRORS.append(f"{group}:{ep.name}: {type(exc).__name__}: {exc}")
                finally:
                    _LOADING_BUILTIN = False


def solvers() -> dict[str, type[Solver]]:
    """All registered solver classes by name."""
    _load()
    return dict(_SOLVERS)


def problems() -> dict[str, type[Problem]]:
    """All registered problem classes by name."""
    _load()
    return dict(_PROBLEMS)


def builtin_names(kind: str) -> set[str]:
    """The names registered by dualfem's own plugins (``kind``: "solver" or "problem"): reserved."""
    _load()
    return set(_BUILTIN[kind])


def entry_point_errors() -> list[str]:
    """Third-party plugins that failed to load, with the reason."""
    _load()
    return list(_ENTRY_POINT_ERRORS)


def get_solver(name: str) -> type[Solver]:
    """The solver class registered as ``name``; InputError listing the known names otherwise."""
    reg = solvers()
    if name not in reg:
        raise InputError(f"unknown solver {name!r}; known solvers: {', '.join(sorted(reg))}")
    return reg[name]


def get_problem(name: str) -> type[Problem]:
    """The problem class registered as ``name``; InputError listing the known names otherwise."""
    reg = problems()
    if name not in reg:
        raise InputError(f"unknown problem {name!r}; known problems: {', '.join(sorted(reg))}")
    return reg[name]


def problem_for_dim(dim: int) -> str:
    """The problem that reads a scene file of dimension ``dim`` naming no problem: the registered
    problem with ``scene_default`` and that ``dim`` (a built-in one first, then by name: a third-party
    plugin cannot take over the built-in choice); InputError naming the dimensions there are."""
    reg = problems()
    builtin = builtin_names("problem")
    found = sorted((n for n, cls in reg.items() if cls.scene_default and cls.dim == dim),
                   key=lambda n: (n not in builtin, n))
    if not found:
        raise InputError(f"dim must be one of {', '.join(map(str, problem_dims()))}, got {dim!r}")
    return found[0]


def problem_for_keys(keys) -> str | None:
    """The problem whose ``claim_keys`` meet ``keys`` (the keys of a scene file naming no problem), a built-in
    one first, then by name; None when no problem claims any of them."""
    reg = problems()
    builtin = builtin_names("problem")
    keys = set(keys)
    found = sorted((n for n, cls in reg.items() if keys & set(getattr(cls, "claim_keys", ()) or ())),
                   key=lambda n: (n not in builtin, n))
    return found[0] if found else None


def problem_dims() -> list[int]:
    """The dimensions a scene file may have: those of the registered problems with ``scene_default``."""
    return sorted({cls.dim for cls in problems().values() if cls.scene_default})
