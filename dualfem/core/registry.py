"""Registries of solver and problem plugins.

Built-in plugins are the modules of ``dualfem.solvers`` and ``dualfem.problems`` (the repository's
top-level folders ``solvers/`` and ``problems/``, mapped into the package by pyproject.toml) (every
module not starting with ``_`` is imported); third-party
packages add theirs through the entry-point groups ``dualfem.solvers`` and ``dualfem.problems``
(each entry point names a plugin class). Registration happens on first use, so importing
dualfem stays cheap and a plugin whose optional dependency is missing is still listed.
"""
from __future__ import annotations

import importlib
import pkgutil
from importlib.metadata import entry_points
from typing import TYPE_CHECKING

from dualfem.core.errors import InputError

if TYPE_CHECKING:  # pragma: no cover
    from dualfem.core.problem import Problem
    from dualfem.core.solver import Solver

_SOLVERS: dict[str, type[Solver]] = {}
_PROBLEMS: dict[str, type[Problem]] = {}
_LOADED = False
_ENTRY_POINT_ERRORS: list[str] = []


def register_solver(cls: type[Solver]) -> type[Solver]:
    """Class decorator: add a solver plugin to the registry under ``cls.name``."""
    if not cls.name:
        raise ValueError(f"solver class {cls.__name__} has no name")
    _SOLVERS[cls.name] = cls
    return cls


def register_problem(cls: type[Problem]) -> type[Problem]:
    """Class decorator: add a problem plugin to the registry under ``cls.name``."""
    if not cls.name:
        raise ValueError(f"problem class {cls.__name__} has no name")
    _PROBLEMS[cls.name] = cls
    return cls


def _load() -> None:
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    import dualfem.problems as builtin_problems
    import dualfem.solvers as builtin_solvers

    for pkg in (builtin_solvers, builtin_problems):
        for info in pkgutil.iter_modules(pkg.__path__):
            if not info.name.startswith("_"):
                importlib.import_module(f"{pkg.__name__}.{info.name}")
    for group, reg in (("dualfem.solvers", register_solver), ("dualfem.problems", register_problem)):
        for ep in entry_points(group=group):
            try:
                reg(ep.load())
            except Exception as exc:  # a broken third-party plugin must not break dualfem
                _ENTRY_POINT_ERRORS.append(f"{group}:{ep.name}: {exc}")


def solvers() -> dict[str, type[Solver]]:
    """All registered solver classes by name."""
    _load()
    return dict(_SOLVERS)


def problems() -> dict[str, type[Problem]]:
    """All registered problem classes by name."""
    _load()
    return dict(_PROBLEMS)


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
