"""The solver plugin contract.

A solver plugin is a subclass of :class:`Solver` that declares

* ``name``: the registry name (``dualfem solve --solver NAME``);
* ``defaults``: every parameter with its default value (unknown parameters are refused);
* ``requires``: importable modules it needs, and ``extra``: the pyproject extra providing them;
* ``tolerance``: the accuracy it promises at default settings, as a relative energy-norm error
  of x and a bound on the evaluator's residuals (the contract tests hold it to that);
* ``exact``: False for methods with an intrinsic error (e.g. penalty), whose answer is
  compared against the reference with ``tolerance`` only;
* ``renamed``: old parameter names still accepted, ``{"old": "new"}`` (a DeprecationWarning
  names the new one).

One parameter vocabulary for every solver: ``tol`` (the relative accuracy the solver aims for),
``max_iter`` (its main iteration cap), ``time_limit`` (seconds, finite default), ``verbose``;
solver-specific parameters keep their own names.

and implements ``setup(qp)`` (work that depends on the matrices only: scaling, factorizations)
and ``solve()`` returning a :class:`~dualfem.solution.Solution`. ``skip(qp)`` returns a reason
string when the solver does not apply to ``qp`` (for example, too large), else None.
"""
from __future__ import annotations

import importlib.util
import math
import warnings
from typing import Any, ClassVar

from dualfem.core.errors import InputError
from dualfem.core.qp import QP
from dualfem.core.solution import Solution


class RenamedParameterWarning(DeprecationWarning):
    """A solver parameter was given by its old name (shown once per call site, even from the CLI)."""


warnings.filterwarnings("default", category=RenamedParameterWarning)


class Solver:
    """Base class of solver plugins (see module docstring)."""

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    defaults: ClassVar[dict[str, Any]] = {}
    requires: ClassVar[tuple[str, ...]] = ()
    extra: ClassVar[str | None] = None
    tolerance: ClassVar[float] = 1e-6
    exact: ClassVar[bool] = True
    renamed: ClassVar[dict[str, str]] = {}
    #: optional: the :class:`dualfem.numerics.linalg.LocalReduction` of the QP this solver built in
    #: ``setup``; the runner's certification then reuses its factorization and dense blocks
    #: (accepted only if it is exactly that class and belongs to the QP being certified)
    reduction: Any = None

    def __init__(self, **params: Any) -> None:
        params = _apply_renames(self.name, self.renamed, params)
        unknown = sorted(set(params) - set(self.defaults))
        if unknown:
            allowed = ", ".join(sorted(self.defaults)) or "(none)"
            raise InputError(f"unknown parameter {unknown[0]!r} for solver {self.name!r}; "
                             f"allowed: {allowed}")
        merged = dict(self.defaults)
        for k, v in params.items():
            merged[k] = _coerce(k, v, self.defaults[k], self.name)
        self.params: dict[str, Any] = merged
        self.validate()
        self.qp: QP | None = None

    # ----------------------------------------------------------- the contract
    def validate(self) -> None:
        """Check ``self.params``; raise InputError naming the parameter and range."""

    @classmethod
    def missing(cls) -> str | None:
        """Return an install hint if a required module is missing, else None."""
        for mod in cls.requires:
            if importlib.util.find_spec(mod) is None:
                hint = f"pip install 'dualfem[{cls.extra}]'" if cls.extra else f"pip install {mod}"
                return f"solver {cls.name!r} needs the Python module {mod!r}: {hint}"
        return None

    @classmethod
    def tolerance_params(cls, tol: float) -> dict[str, Any]:
        """Solver parameters that target a relative accuracy ``tol`` (for benchmark tiers).

        Plugins map ``tol`` to their own options (e.g. OSQP's eps_abs/eps_rel); the default
        returns no change.
        """
        return {}

    def skip(self, qp: QP) -> str | None:
        """Reason why this solver does not apply to ``qp``, or None."""
        return None

    def setup(self, qp: QP) -> None:
        """Matrix-dependent work (timed as setup)."""
        self.qp = qp

    def solve(self) -> Solution:  # pragma: no cover - abstract
        """Solve the QP given to :meth:`setup` (timed as solve)."""
        raise NotImplementedError


def _apply_renames(solver: str, renamed: dict[str, str], params: dict[str, Any]) -> dict[str, Any]:
    """Map deprecated parameter names to the new ones, with a DeprecationWarning each."""
    if not renamed or not set(params) & set(renamed):
        return params
    out = {k: v for k, v in params.items() if k not in renamed}
    for old, value in params.items():
        if old not in renamed:
            continue
        new = renamed[old]
        warnings.warn(f"parameter {old!r} of solver {solver!r} is deprecated: use {new!r}",
                      RenamedParameterWarning, stacklevel=4)
        if new in out and out[new] != value:
            raise InputError(f"parameters {old!r} (deprecated) and {new!r} of solver {solver!r} "
                             f"disagree: {value!r} vs {out[new]!r}; give only {new!r}")
        out[new] = value
    return out


def _coerce(key: str, value: Any, default: Any, solver: str, owner: str = "solver") -> Any:
    """Convert a (possibly string, from --set) value to the type of its default."""
    where = (f"parameter {key!r} of solver {solver!r}" if owner == "solver"
             else f"scene parameter {key!r} of problem {solver!r}")
    if isinstance(default, bool):
        if isinstance(value, str):
            if value.lower() in ("1", "true", "yes", "on"):
                return True
            if value.lower() in ("0", "false", "no", "off"):
                return False
            raise InputError(f"{where} must be true or false, got {value!r}")
        return bool(value)
    if isinstance(default, (int, float)) and not isinstance(default, bool) and isinstance(value, bool):
        raise InputError(f"{where} must be a number, got {value!r}")
    if isinstance(default, int) and not isinstance(default, bool):
        try:
            f = float(value)
        except (TypeError, ValueError):
            raise InputError(f"{where} must be an integer, got {value!r}") from None
        if not math.isfinite(f) or f != int(f):
            raise InputError(f"{where} must be an integer, got {value!r}")
        return int(f)
    if isinstance(default, float) or (default is None and _is_number(value)):
        try:
            return float(value)
        except (TypeError, ValueError):
            raise InputError(f"{where} must be a number, got {value!r}") from None
    return value


def _is_number(v: Any) -> bool:
    try:
        float(v)
        return not isinstance(v, bool)
    except (TypeError, ValueError):
        return False


def positive(solver: Solver, *names: str) -> None:
    """Raise InputError unless every named parameter is a finite number > 0."""
    for nm in names:
        v = solver.params[nm]
        if v is None:
            continue
        if not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise InputError(f"parameter {nm!r} of solver {solver.name!r} must be a finite "
                             f"number > 0, got {v!r}")
