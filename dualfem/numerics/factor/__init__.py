"""The K-solve backends behind one interface (:mod:`.base`), in one registry.

Registered: the direct factorizations ``cudss`` (a GPU's; detection only so far: :mod:`.cudss`), ``pardiso``,
``cholmod``, ``superlu`` (fastest first) and the AMG
K-solve ``amg`` (``direct = False``: :mod:`.amg`). A new backend (a GPU or a distributed one) is one module
with a :class:`Backend` subclass (``available``, ``missing``, ``make`` -> a :class:`Factorization` with
``analyze``/``factorize``/``solve`` of one right-hand side or a block, ``peak_bytes``: its memory model) and
one :func:`register` call. No code outside a backend's own module branches on its name.

``available()`` lists the installed direct backends, fastest first; ``choose(name)`` returns one: the name
given, else the linear-algebra context's (:mod:`dualfem.numerics.la`: ``--factor``, a Workspace's, else
the environment variable ``DUALFEM_FACTOR``, else the fastest installed one).

Preference pardiso > cholmod > superlu: by time and memory on large scenes
(benchmarks/factor_backends.py; the numbers: docs/measurements.md).
"""
from __future__ import annotations

import os

from dualfem.core.errors import InputError

from .amg import AmgBackend
from .base import Backend, Factorization, Forward, schur_by_solves
from .cholmod import CholmodBackend
from .cudss import CudssBackend
from .pardiso import PardisoBackend
from .superlu import SuperLUBackend

__all__ = ["Backend", "Factorization", "Forward", "available", "choose", "names", "set_default", "get_default",
           "get_default_unset", "is_available",
           "missing_fast_backend_hint", "schur_by_solves", "ENV", "register", "registered", "backend_class"]

#: environment variable naming the backend
ENV = "DUALFEM_FACTOR"
#: every registered backend, the direct ones fastest first (a new backend: one module with a
#: :class:`Backend` subclass and :func:`register` of it)
_REGISTRY: dict[str, type[Backend]] = {}
_AVAILABLE: dict[str, bool] = {}
_HINTED = False
#: unknowns from which the missing-PARDISO advice is given (N = 256 of f2: 132 k unknowns)
HINT_MIN_UNKNOWNS = 130_000


def register(cls: type[Backend]) -> type[Backend]:
    """Register a backend class under ``cls.name`` (after the ones already registered; usable as a
    decorator). ValueError for a name taken by another class."""
    key = str(cls.name).strip().lower()
    if key in _REGISTRY and _REGISTRY[key] is not cls:
        raise ValueError(f"a backend named {key!r} is registered already ({_REGISTRY[key].__qualname__})")
    _REGISTRY[key] = cls
    _AVAILABLE.pop(key, None)
    return cls


for _cls in (CudssBackend, PardisoBackend, CholmodBackend, SuperLUBackend, AmgBackend):
    register(_cls)


def registered(direct: bool | None = None) -> list[str]:
    """Names of the registered backends (``direct``: only the direct factorizations, or only the others)."""
    return [k for k, c in _REGISTRY.items() if direct is None or c.direct == direct]


def backend_class(name: str, source: str = "backend") -> type[Backend]:
    """The registered class named ``name`` (any kind, installed or not); InputError naming ``source``
    and the registered names otherwise."""
    key = str(name).strip().lower()
    if key not in _REGISTRY:
        raise InputError(f"{source} must be one of {', '.join(_REGISTRY)}, got {name!r}")
    return _REGISTRY[key]


def names() -> list[str]:
    """Every known direct factorization backend (what ``factor=`` may name), fastest first."""
    return registered(direct=True)


def is_available(name: str) -> bool:
    """True when the registered backend ``name`` can run here (cached per process)."""
    key = str(name).strip().lower()
    if key not in _AVAILABLE:
        _AVAILABLE[key] = bool(backend_class(key).available())
    return _AVAILABLE[key]


def available() -> list[str]:
    """Names of the installed direct factorization backends, fastest first."""
    return [k for k in names() if is_available(k)]


def _check(name: str, source: str) -> str:
    key = str(name).strip().lower()
    if key not in names():
        raise InputError(f"{source} must be one of {', '.join(names())} (installed here: "
                         f"{', '.join(available())}), got {name!r}")
    if key not in available():
        raise InputError(f"{source} = {key!r}: {_REGISTRY[key].missing()} (installed here: {', '.join(available())})")
    return key


def set_default(name: str | None) -> None:
    """Process-wide backend (``--factor NAME``): sets the factor of the linear-algebra context
    (:func:`dualfem.numerics.la.use`); None returns to the default context (environment variable / fastest)."""
    from dualfem.numerics import la

    la.use(None if name is None else la.current().with_(factor=_check(name, "factor")))


def get_default_unset() -> str:
    """The backend without a process-wide choice: ``DUALFEM_FACTOR``, else the fastest installed."""
    env = os.environ.get(ENV, "").strip()
    if env:
        return _check(env, f"environment variable {ENV}")
    return available()[0]


def get_default() -> str:
    """Name of the backend :func:`choose` returns without an argument: the linear-algebra context's
    (:func:`dualfem.numerics.la.current`)."""
    from dualfem.numerics import la

    return la.current().factor


def choose(name: str | Backend | None = None) -> Backend:
    """The backend named (or given), else the process default (see module docstring)."""
    if isinstance(name, Backend):
        return name
    key = _check(name, "factor") if name is not None else get_default()
    return _REGISTRY[key]()


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
