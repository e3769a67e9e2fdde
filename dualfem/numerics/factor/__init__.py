"""Sparse SPD factorization backends behind one interface (:mod:`.base`).

``available()`` lists the installed backends, fastest first; ``choose(name)`` returns one:
the name given, else the process-wide choice (:func:`set_default`, e.g. from ``--factor``),
else the environment variable ``DUALFEM_FACTOR``, else the fastest installed one.

Preference pardiso > cholmod > superlu: by time and memory on large scenes
(benchmarks/factor_backends.py; the numbers: docs/measurements.md).
"""
from __future__ import annotations

import os

from dualfem.core.errors import InputError

from .base import Backend, Factorization, Forward, schur_by_solves
from .cholmod import CholmodBackend
from .pardiso import PardisoBackend
from .superlu import SuperLUBackend

__all__ = ["Backend", "Factorization", "Forward", "available", "choose", "names", "set_default", "get_default",
           "missing_fast_backend_hint", "schur_by_solves", "ENV"]

#: environment variable naming the backend
ENV = "DUALFEM_FACTOR"
#: every known backend, fastest first
_BACKENDS: dict[str, type[Backend]] = {"pardiso": PardisoBackend, "cholmod": CholmodBackend,
                                       "superlu": SuperLUBackend}
_DEFAULT: str | None = None
_AVAILABLE: dict[str, bool] = {}
_HINTED = False
#: unknowns from which the missing-PARDISO advice is given (N = 256 of f2: 132 k unknowns)
HINT_MIN_UNKNOWNS = 130_000


def names() -> list[str]:
    """Every known backend name, fastest first."""
    return list(_BACKENDS)


def available() -> list[str]:
    """Names of the installed backends, fastest first."""
    for k, cls in _BACKENDS.items():
        if k not in _AVAILABLE:
            _AVAILABLE[k] = bool(cls.available())
    return [k for k in _BACKENDS if _AVAILABLE[k]]


def _check(name: str, source: str) -> str:
    key = str(name).strip().lower()
    if key not in _BACKENDS:
        raise InputError(f"{source} must be one of {', '.join(_BACKENDS)} (installed here: "
                         f"{', '.join(available())}), got {name!r}")
    if key not in available():
        raise InputError(f"{source} = {key!r} is not installed here (installed: {', '.join(available())}); "
                         f"install it with: {_BACKENDS[key].install_hint}")
    return key


def set_default(name: str | None) -> None:
    """Process-wide backend (``--factor NAME``); None returns to env var / fastest."""
    global _DEFAULT
    _DEFAULT = None if name is None else _check(name, "factor")


def get_default() -> str:
    """Name of the backend :func:`choose` returns without an argument."""
    if _DEFAULT is not None:
        return _DEFAULT
    env = os.environ.get(ENV, "").strip()
    if env:
        return _check(env, f"environment variable {ENV}")
    return available()[0]


def choose(name: str | Backend | None = None) -> Backend:
    """The backend named (or given), else the process default (see module docstring)."""
    if isinstance(name, Backend):
        return name
    key = _check(name, "factor") if name is not None else get_default()
    return _BACKENDS[key]()


def missing_fast_backend_hint(n_unknowns: int) -> str | None:
    """Advice to install PARDISO, once per process, for n_unknowns >= HINT_MIN_UNKNOWNS when missing."""
    global _HINTED
    if _HINTED or n_unknowns < HINT_MIN_UNKNOWNS or "pardiso" in available():
        return None
    _HINTED = True
    return (f"{n_unknowns} unknowns: MKL PARDISO is not installed; it makes the exact solvers' factorization "
            f"2.2-3.6x faster than SuperLU with less than half the memory (f2 N = 512 on 2 cores: 3.8-5.7 s "
            f"vs 12.7-13.6 s, 1.3 GB vs 3.0 GB peak). Install it with: pip install 'dualfem[pardiso]'")


def from_param(solver) -> str | None:
    """The backend a solver's ``factor`` parameter names ("auto" -> None: the process-wide choice).

    Raises InputError for an unknown or uninstalled name (call it in ``Solver.validate``).
    """
    v = solver.params.get("factor", "auto")
    if v is None or str(v).strip().lower() in ("", "auto"):
        return None
    return _check(v, f"parameter 'factor' of solver {solver.name!r} ('auto' or a backend)")
