"""The linear-algebra context of a run: which factorization backend, which dual operator, how many threads,
how much memory; chosen once, shared by the solver and the certificate.

    from dualfem.numerics.la import LinearAlgebra, current
    la = LinearAlgebra.default().with_(factor="superlu", max_memory=8e9)
    with la.active():                 # or Workspace(scene, factor="superlu"): the workspace owns one
        ...                           # every solve, setup and certificate in here reads current()

Fields (frozen; :meth:`LinearAlgebra.with_` makes a changed copy):

* ``factor``: the direct factorization backend (a name registered in :mod:`dualfem.numerics.factor`,
  installed here); default: the environment variable ``DUALFEM_FACTOR``, else the fastest installed;
* ``operator``: the dual-operator kind a dual solver gets when its ``operator`` parameter is ``auto``
  (one of :data:`dualfem.numerics.operator_choice.OPERATORS`; ``auto``: by size and memory);
* ``ksolve``: the non-direct K-solve backend used where no factorization of K fits (``amg``);
* ``threads``: the threads the run asked for (None: all cores; applied by
  :func:`dualfem.numerics.threads.set_threads`);
* ``max_memory``: the memory budget in bytes (None: what the machine has available now); the operator
  choice compares its estimates with ``min(available, max_memory)``.

Who chooses: the CLI (``--factor``, ``--threads``, ``--max-memory``: :func:`from_args`, then :func:`use`), a
:class:`~dualfem.experiments.workspace.Workspace` (its ``la``, active while it sets up and solves), or the
environment variable (read by :meth:`LinearAlgebra.default`). A solver's parameters select within it:
``factor`` (a backend name, ``auto``: the context's), ``operator`` (``auto``: the context's ``operator``) and
``keep_factors`` (how many face factorizations the matrix-free Newton matrix keeps). Child processes
(the bench harness) get the context through :meth:`LinearAlgebra.child_env`.
"""
from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import asdict, dataclass, replace
from typing import Any

from dualfem.core.errors import InputError
from dualfem.numerics import factor as _factor

__all__ = ["LinearAlgebra", "chosen", "current", "use", "from_args", "ENV"]

#: environment variable naming the factorization backend (read only: nothing here writes it)
ENV = _factor.ENV


@dataclass(frozen=True)
class LinearAlgebra:
    """One run's linear-algebra strategy (module docstring)."""

    factor: str
    operator: str = "auto"
    ksolve: str = "amg"
    threads: int | None = None
    max_memory: int | None = None

    def __post_init__(self) -> None:
        from dualfem.numerics.operator_choice import OPERATORS

        object.__setattr__(self, "factor", _factor._check(self.factor, "factor"))
        if self.operator not in OPERATORS:
            raise InputError(f"operator must be one of {', '.join(OPERATORS)}, got {self.operator!r}")
        if self.ksolve not in _factor.registered(direct=False):
            raise InputError(f"ksolve must be one of {', '.join(_factor.registered(direct=False))}, "
                             f"got {self.ksolve!r}")
        if self.max_memory is not None:
            if not self.max_memory > 0:
                raise InputError(f"max_memory must be a positive number of bytes, got {self.max_memory!r}")
            object.__setattr__(self, "max_memory", int(self.max_memory))

    @classmethod
    def default(cls) -> LinearAlgebra:
        """The context without a choice: ``DUALFEM_FACTOR`` if set, else the fastest installed backend."""
        return cls(_factor.get_default_unset())

    def with_(self, **changes: Any) -> LinearAlgebra:
        """A copy with ``changes`` (None values keep the field)."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})

    def as_dict(self) -> dict:
        return asdict(self)

    # ------------------------------------------------------------------ what the solver and certificate ask
    def backend(self, name: str | None = None) -> _factor.Backend:
        """The direct factorization backend: ``name`` (a solver's ``factor`` parameter) if given, else the
        context's."""
        return _factor.choose(self.factor if name is None else name)

    def memory_limit(self) -> int:
        """Bytes a new allocation may use: the memory available now, capped by ``max_memory``."""
        from dualfem.numerics import memory

        have = memory.available_bytes()
        return have if self.max_memory is None else min(have, self.max_memory)

    def choose_operator(self, qp, asked: str | None = None, factor: str | None = None) -> tuple[str, str]:
        """(kind, why): :func:`dualfem.numerics.operator_choice.choose_operator` with this context's backend
        (or ``factor``), memory budget and, for ``asked`` None or ``auto``, its ``operator``."""
        from dualfem.numerics.operator_choice import choose_operator

        asked = self.operator if asked in (None, "auto") else asked
        return choose_operator(qp, asked, limit_bytes=self.memory_limit(), backend=factor or self.factor,
                               ksolve=self.ksolve)

    def ksolver(self, qp, reduction=None, ksolve: str = "auto"):
        """The certificate's K-solver of ``qp`` in this context (:class:`dualfem.numerics.ksolver.KSolver`)."""
        from dualfem.numerics.ksolver import KSolver

        return KSolver(qp, reduction=reduction, ksolve=ksolve, la=self)

    # ------------------------------------------------------------------ scope
    @contextlib.contextmanager
    def active(self) -> Iterator[LinearAlgebra]:
        """Make this the process's context inside the block (the previous one afterwards)."""
        before = _CURRENT
        use(self)
        try:
            yield self
        finally:
            use(before)

    def child_env(self) -> dict[str, str]:
        """Environment entries that make a child Python process start with this context's backend."""
        return {ENV: self.factor}


_CURRENT: LinearAlgebra | None = None


def current() -> LinearAlgebra:
    """The context chosen for this run (:func:`use`, a Workspace's :meth:`~LinearAlgebra.active`), else
    :meth:`LinearAlgebra.default` (read now: a changed environment variable counts)."""
    return _CURRENT if _CURRENT is not None else LinearAlgebra.default()


def chosen() -> LinearAlgebra | None:
    """The context chosen explicitly for this process (:func:`use`), None when it runs on the default."""
    return _CURRENT


def use(la: LinearAlgebra | None) -> LinearAlgebra:
    """Choose the process's context (None: back to the default); returns the current one."""
    global _CURRENT
    if la is not None and not isinstance(la, LinearAlgebra):
        raise TypeError(f"use() takes a LinearAlgebra or None, got {type(la).__name__}")
    _CURRENT = la
    return current()


def from_args(args) -> LinearAlgebra:
    """The context of a command line: ``--factor``, ``--threads``, ``--max-memory`` (GB) where the command has
    them, over the default (InputError for an unknown or missing backend)."""
    mm = getattr(args, "max_memory", None)
    threads = getattr(args, "threads", None)
    return LinearAlgebra.default().with_(factor=getattr(args, "factor", None) or None,
                                         threads=threads if isinstance(threads, int) else None,
                                         max_memory=None if mm is None else float(mm) * 1e9)
