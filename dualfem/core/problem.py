"""The problem plugin contract.

A problem plugin is a subclass of :class:`Problem` declaring ``name``, ``defaults`` (every scene
parameter with its default), optionally ``presets`` (named scenes, e.g. the paper's ``f1``),
and implementing :meth:`Problem.build` returning a :class:`~dualfem.qp.QP`. Problems return plain
scipy.sparse / numpy data and know nothing of solvers.
"""
from __future__ import annotations

from typing import Any, ClassVar

from dualfem.core.errors import InputError, MissingDependency, missing_module
from dualfem.core.qp import QP
from dualfem.core.solver import _coerce


class Problem:
    """Base class of problem plugins."""

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    defaults: ClassVar[dict[str, Any]] = {}
    presets: ClassVar[dict[str, dict[str, Any]]] = {}
    requires: ClassVar[tuple[str, ...]] = ()     # importable modules build() needs
    extra: ClassVar[str | None] = None           # the pyproject extra providing them

    @classmethod
    def missing(cls) -> str | None:
        """Return an install hint if a module ``build()`` needs is missing, else None."""
        return missing_module(f"problem {cls.name!r}", cls.requires, cls.extra)

    def __init__(self, **params: Any) -> None:
        reason = self.missing()
        if reason:
            raise MissingDependency(reason)
        unknown = sorted(set(params) - set(self.defaults))
        if unknown:
            raise InputError(f"unknown scene key {unknown[0]!r} for problem {self.name!r}; "
                             f"allowed: {', '.join(sorted(self.defaults))}")
        merged = dict(self.defaults)
        for k, v in params.items():
            d = self.defaults[k]
            merged[k] = _coerce(k, v, d, self.name, owner="problem") if isinstance(d, (int, float)) else v
        self.params: dict[str, Any] = merged
        self.validate()

    def validate(self) -> None:
        """Check ``self.params``; raise InputError naming the parameter and its range."""

    def size_estimate(self) -> tuple[int, str] | None:
        """(estimated number of unknowns, a label such as "N=512") before assembly, or None if unknown.

        Used to refuse, before any allocation, a scene that cannot fit in memory."""
        return None

    def build(self) -> QP:  # pragma: no cover - abstract
        """Assemble the QP of this scene."""
        raise NotImplementedError
