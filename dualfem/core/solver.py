"""The solver plugin contract.

A solver plugin is a subclass of :class:`Solver` that declares

* ``name``: the registry name (``dualfem solve --solver NAME``);
* ``defaults``: every parameter with its default value (unknown parameters are refused);
* ``requires``: importable modules it needs, and ``extra``: the pyproject extra providing them;
* ``tolerance``: the accuracy it promises at default settings, as a relative energy-norm error
  of x and a bound on the evaluator's residuals (the contract tests hold it to that);
* ``exact``: False for methods with an intrinsic error (e.g. penalty), whose answer is
  compared against the reference with ``tolerance`` only;
* ``reference`` (default False): the solver may serve as the trusted reference every other run
  is measured against (:mod:`dualfem.experiments.reference`; only an ``exact`` solver qualifies,
  and each of its answers must still pass the policy's checks); ``reference_rank`` orders the
  reference solvers (smallest first, then the name) and ``reference_params`` are the parameters
  a reference solve uses (e.g. refinement to the rounding floor). Nothing in the framework names
  a solver: which one is the reference is this declaration (:func:`reference_solvers`);
* ``renamed``: old parameter names still accepted, ``{"old": "new"}`` (a DeprecationWarning
  names the new one);
* ``ranges``: the allowed values of each parameter (see :func:`check_value`): an interval string
  such as ``"(0, inf)"``, ``"[1, inf)"`` or ``"(0, 2]"`` (integers when the default is an int),
  a tuple of allowed strings, ``bool``, or None for a value only ``validate()`` can check (a
  backend name). The shared vocabulary's ranges (:data:`COMMON_RANGES`) apply to every solver
  that has the parameter; ``__init__`` and the runner check every declared range before
  ``validate()`` and before any library sees the value.

One parameter vocabulary for every solver: ``tol`` (the relative accuracy the solver aims for),
``max_iter`` (its main iteration cap), ``time_limit`` (seconds, finite default), ``verbose``;
solver-specific parameters keep their own names.

and implements ``setup(qp)`` (work that depends on the matrices only: scaling, factorizations)
and ``solve()`` returning a :class:`~dualfem.solution.Solution`. ``skip(qp)`` returns a reason
string when the solver does not apply to ``qp`` (for example, too large), else None. ``accepts``: the
constraint laws it handles (:mod:`dualfem.core.laws`; default ``("signorini",)``); the runner skips it,
before ``skip()``, on a QP with a block of another law.

**Iterates (optional).** A solver with an outer iteration may call
``self.report_iterate(iteration, x, mu)`` once per iteration (:meth:`Solver.report_iterate`): a no-op
unless the runner attached an iterate monitor for this solve (a bench with ``curves = true``:
:mod:`dualfem.experiments.curves`), which samples the iterates into a convergence curve. A solver
that never calls it is a point in a work-precision diagram, as before.
"""
from __future__ import annotations

import math
import re
import warnings
from typing import Any, ClassVar

import numpy as np

from dualfem.core.errors import InputError, missing_module
from dualfem.core.qp import QP
from dualfem.core.solution import Solution

#: the solver families a solver may declare (``Solver.family``), in the order figures facet them:
#: ``dual`` (methods on the contact dual), ``interior point`` (interior point / conic), ``first-order``
#: (ADMM, proximal and augmented-Lagrangian methods), ``active set``, ``other``
SOLVER_FAMILIES: tuple[str, ...] = ("dual", "interior point", "first-order", "active set", "other")


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
    #: may serve as the trusted reference (exact solvers only; see the module docstring)
    reference: ClassVar[bool] = False
    #: order among the reference solvers: smallest first (ties: by name)
    reference_rank: ClassVar[int] = 100
    #: parameters of a reference solve (merged over ``defaults``)
    reference_params: ClassVar[dict[str, Any]] = {}
    #: the solver's family (one of :data:`SOLVER_FAMILIES`): figures derive its colour and marker from it
    family: ClassVar[str] = "other"
    #: the names of the constraint laws (:attr:`dualfem.core.laws.Law.name`) it handles; the runner skips it,
    #: with the reason, on a QP with a block of any other law (:func:`unhandled_law`)
    accepts: ClassVar[tuple[str, ...]] = ("signorini",)
    #: optional: the :class:`dualfem.numerics.linalg.LocalReduction` of the QP this solver built in
    #: ``setup``; the runner's certification then reuses its factorization and dense blocks
    #: (accepted only if it is exactly that class and belongs to the QP being certified)
    reduction: Any = None
    ranges: ClassVar[dict[str, Any]] = {}
    #: the iterate monitor the runner attached for the current ``solve()`` (None: none attached);
    #: set and cleared by :func:`dualfem.experiments.runner.run`, never by the plugin
    _iterate_monitor: Any = None

    def __init__(self, **params: Any) -> None:
        params = _apply_renames(self.name, self.renamed, params)
        backend = _backend_options(self, params)
        unknown = sorted(set(params) - set(self.defaults) - set(backend))
        if unknown:
            allowed = ", ".join(sorted(self.defaults)) or "(none)"
            own = (f"; {self.name}'s backend options (from the installed library): {', '.join(sorted(backend))}"
                   if backend else "")
            raise InputError(f"unknown parameter {unknown[0]!r} for solver {self.name!r}; "
                             f"allowed: {allowed}{own}")
        merged = dict(self.defaults)
        words = self.allowed()
        for k, v in params.items():
            default = self.defaults[k] if k in self.defaults else backend[k]
            merged[k] = _coerce(k, v, default, self.name, expect=words.get(k))
        self.params: dict[str, Any] = merged
        self.check_params()
        self.validate()
        check_declared(self)          # validate() may set an instance tolerance (cvxpy: per backend)
        self.qp: QP | None = None

    @classmethod
    def variant_family(cls, variant: str) -> str:
        """The family (one of :data:`SOLVER_FAMILIES`) of a variant of this solver, ``variant`` being the
        text after the solver's name in a series label (``"[r=10]"``, ``":OSQP"``; ``""`` for the solver
        itself): :attr:`family`, unless a parameter changes the method (cvxpy's backend), in which case
        the solver overrides this. Figures read it (:func:`dualfem.post.style.family`)."""
        return cls.family

    @classmethod
    def param_ranges(cls) -> dict[str, Any]:
        """The declared allowed values of every parameter: ``ranges``, plus the shared vocabulary's
        (:data:`COMMON_RANGES`) for a parameter whose default lies in it (a third-party plugin whose
        ``time_limit = 0`` means 'none' keeps its own meaning, checked by its ``validate``)."""
        table = {}
        for k, d in cls.defaults.items():
            if k in cls.ranges:
                table[k] = cls.ranges[k]
            elif k in COMMON_RANGES and _fits(k, d, COMMON_RANGES[k], cls.name):
                table[k] = COMMON_RANGES[k]
        return table

    @classmethod
    def allowed(cls) -> dict[str, str]:
        """The declared allowed values in words, per parameter (for messages and ``dualfem list``)."""
        return {k: describe_range(spec, isinstance(cls.defaults[k], int) and not isinstance(cls.defaults[k], bool))
                for k, spec in cls.param_ranges().items() if spec is not None}

    def check_params(self) -> None:
        """Raise InputError for the first parameter outside its declared range (see :func:`check_value`),
        or for a declared ``tolerance`` / ``exact`` outside the contract (:func:`check_declared`)."""
        check_declared(self)
        params = getattr(self, "params", None) or {}      # a plugin may override __init__
        if not isinstance(params, dict):
            raise InputError(f"solver {self.name!r}: params must be a dict of parameters, got {type(params).__name__}")
        for key, spec in self.param_ranges().items():
            if key in params:
                check_value(key, params[key], spec, self.defaults[key], self.name)

    # ----------------------------------------------------------- the contract
    def validate(self) -> None:
        """Check ``self.params``; raise InputError naming the parameter and range."""

    @classmethod
    def missing(cls) -> str | None:
        """Return an install hint if a required module is missing, else None."""
        return missing_module(f"solver {cls.name!r}", cls.requires, cls.extra)

    @classmethod
    def tolerance_params(cls, tol: float) -> dict[str, Any]:
        """Solver parameters that target a relative accuracy ``tol`` (for benchmark tiers).

        Plugins map ``tol`` to their own options (e.g. OSQP's eps_abs/eps_rel); the default
        returns no change.
        """
        return {}

    @classmethod
    def backend_options(cls, params: dict[str, Any]) -> dict[str, Any]:
        """The wrapped library's own settings this solver passes through, ``{name: default}``.

        Read from the installed library (empty when it is missing or the solver wraps none, the
        default); ``params``: the parameters given so far (a solver whose backend is a parameter, like
        cvxpy's ``solver``, answers for that backend). A parameter that is neither in ``defaults`` nor
        here is refused with both lists; one that is here is coerced to the type of the library's
        default, kept in ``self.params`` under the library's name and handed to the library as given
        (``-s 'osqp[rho=0.1]'``). Names in ``defaults`` or ``renamed`` keep dualfem's meaning.
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

    def report_iterate(self, iteration: int, x: Any, mu: Any) -> None:
        """Report the iterate of outer iteration ``iteration`` (call it once per iteration from ``solve``).

        ``x``: the QP's unknowns, shape (n,); ``mu``: the multipliers in the Solution's convention (contact
        forces, mu >= 0 at the answer), shape (m,) for ``B x >= 0`` alone and (``QP.m_total``,), every block's
        stacked, for a QP with constraint blocks (friction). Either may be a zero-argument
        callable returning the array (e.g. ``lambda: op.x_of(mu)`` for a dual method): it is called only
        when the monitor keeps this iterate, so an unsampled iteration costs one attribute read and one
        call. Without a monitor (every ``dualfem solve``, compare, stress, a bench without ``curves``)
        it does nothing. The monitor copies what it keeps, and the time spent in it is excluded from the
        run's solve time; it never raises into the solver (a bad iterate ends the sampling, with a note).
        """
        monitor = self._iterate_monitor
        if monitor is not None:
            monitor.report(iteration, x, mu)


def unhandled_law(solver: Solver | type[Solver], qp: QP) -> str | None:
    """Why ``solver`` does not apply to ``qp`` by its constraint laws (a block whose law's name is not in
    the solver's ``accepts``), or None: a solver is never run on a law it does not declare."""
    accepts = getattr(solver, "accepts", ("signorini",))
    accepts = (accepts,) if isinstance(accepts, str) else tuple(accepts or ())
    for k, block in enumerate(qp.constraints):
        if block.m and block.law.name not in accepts:
            return (f"solver {_who(solver)} does not handle the {block.law.name!r} law of constraint block {k} "
                    f"(it accepts: {', '.join(map(repr, accepts)) or 'none'})")
    return None


def declared_tolerance(solver: Solver | type[Solver]) -> float:
    """The ``tolerance`` a solver (class or instance) declares, checked: a finite number in (0, 1).

    Raises InputError otherwise, naming the solver and the value: the runner certifies ``solved``
    claims against this number, so NaN (every comparison false), inf or 10 would certify anything.
    """
    tol = getattr(solver, "tolerance", None)
    if isinstance(tol, (bool, np.bool_)) or not isinstance(tol, (int, float, np.integer, np.floating)) \
            or not math.isfinite(tol) or not 0 < tol < 1:
        raise InputError(f"solver plugin {_who(solver)} declares tolerance = {tol!r}: the declared tolerance "
                         f"must be a finite number in (0, 1) (the relative accuracy its 'solved' answers promise)")
    return float(tol)


def check_declared(solver: Solver | type[Solver]) -> tuple[float, bool]:
    """(tolerance, exact) as declared by a solver class or instance, checked (InputError otherwise):
    ``tolerance`` a finite number in (0, 1), ``exact`` a bool."""
    tol = declared_tolerance(solver)
    exact = getattr(solver, "exact", None)
    if not isinstance(exact, (bool, np.bool_)):
        raise InputError(f"solver plugin {_who(solver)} declares exact = {exact!r}: it must be True or False")
    return tol, bool(exact)


def _who(solver: Any) -> str:
    cls = solver if isinstance(solver, type) else type(solver)
    return f"{getattr(solver, 'name', '?')!r} ({cls.__module__}.{cls.__qualname__})"


COMMON_RANGES: dict[str, Any] = {"tol": "(0, inf)", "max_iter": "[1, inf)", "time_limit": "(0, inf)",
                                 "verbose": bool}
"""Ranges of the shared vocabulary: tol > 0, max_iter >= 1, a finite time_limit > 0 (seconds)."""

_INTERVAL = re.compile(r"^\s*([\[(])\s*([^,\s]+)\s*,\s*([^\])\s]+)\s*([\])])\s*$")


def reference_solvers(registry: dict[str, type[Solver]] | None = None,
                      installed: bool = True) -> list[tuple[str, type[Solver]]]:
    """(name, class) of the solvers of ``registry`` (default: every registered solver) that declare
    ``reference`` and ``exact`` (with ``installed``, only those whose dependencies are importable),
    preferred first: by ``reference_rank``, then by name."""
    if registry is None:
        from dualfem.core.registry import solvers

        registry = solvers()
    found = [(n, c) for n, c in registry.items()
             if getattr(c, "reference", False) and c.exact and (not installed or c.missing() is None)]
    return sorted(found, key=lambda nc: (getattr(nc[1], "reference_rank", 100), nc[0]))


def interval(spec: str) -> tuple[float, float, bool, bool]:
    """``"(0, inf)"`` -> (lo, hi, lo_closed, hi_closed); a bracket means the end is allowed."""
    m = _INTERVAL.match(spec)
    if not m:
        raise ValueError(f"bad interval {spec!r}: write e.g. '(0, inf)' or '[1, 100]'")
    return float(m.group(2)), float(m.group(3)), m.group(1) == "[", m.group(4) == "]"


def describe_range(spec: Any, integer: bool = False) -> str:
    """Words for an allowed range: 'a finite number > 0', 'an integer in [0, 100]', 'one of a, b'."""
    if spec is bool:
        return "true or false"
    if isinstance(spec, tuple):
        return "one of " + ", ".join(map(str, spec))
    lo, hi, lo_c, hi_c = interval(spec)
    kind = "an integer" if integer else "a finite number"
    if hi == math.inf:
        return f"{kind} {'>=' if lo_c else '>'} {lo:g}"
    if lo == -math.inf:
        return f"{kind} {'<=' if hi_c else '<'} {hi:g}"
    return f"{kind} in {'[' if lo_c else '('}{lo:g}, {hi:g}{']' if hi_c else ')'}"


def check_value(key: str, value: Any, spec: Any, default: Any, solver: str) -> None:
    """Raise InputError unless ``value`` of parameter ``key`` lies in ``spec`` (see ``Solver.ranges``).

    Numbers must be finite and not booleans; an int default asks for an integer.
    """
    if spec is None:
        return
    integer = isinstance(default, int) and not isinstance(default, bool)
    if spec is bool:
        ok = isinstance(value, (bool, np.bool_))
    elif isinstance(spec, tuple):
        ok = isinstance(value, str) and value in spec
    else:
        lo, hi, lo_c, hi_c = interval(spec)
        ok = bool(isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
              and math.isfinite(value) and (not integer or float(value) == int(value))
              and (lo <= value if lo_c else lo < value) and (value <= hi if hi_c else value < hi))
    if not ok:
        raise InputError(f"parameter {key!r} of solver {solver!r} must be {describe_range(spec, integer)}, "
                         f"got {value!r}")


def _fits(key: str, default: Any, spec: Any, solver: str) -> bool:
    try:
        check_value(key, default, spec, default, solver)
    except InputError:
        return False
    return True


def _backend_options(solver: Solver, params: dict[str, Any]) -> dict[str, Any]:
    """``solver.backend_options`` for the given parameters, less dualfem's own names (only asked when a
    parameter is not in ``defaults``)."""
    if not set(params) - set(solver.defaults):
        return {}
    given = {k: v for k, v in params.items() if k in solver.defaults}
    opts = type(solver).backend_options({**solver.defaults, **given})
    return {k: v for k, v in (opts or {}).items() if k not in solver.defaults and k not in solver.renamed}


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


def _coerce(key: str, value: Any, default: Any, solver: str, owner: str = "solver", expect: str | None = None) -> Any:
    """Convert a (possibly string, from --set) value to the type of its default.

    ``expect``: the allowed values in words (a declared range), used in the error message.
    """
    where = (f"parameter {key!r} of solver {solver!r}" if owner == "solver"
             else f"scene parameter {key!r} of problem {solver!r}")

    def refuse(what: str) -> InputError:
        return InputError(f"{where} must be {expect or what}, got {value!r}")

    if isinstance(default, bool):
        if isinstance(value, str):
            if value.lower() in ("1", "true", "yes", "on"):
                return True
            if value.lower() in ("0", "false", "no", "off"):
                return False
            raise refuse("true or false")
        if isinstance(value, (bool, np.bool_)) or (isinstance(value, (int, np.integer)) and value in (0, 1)):
            return bool(value)
        raise refuse("true or false")
    if isinstance(default, (int, float)) and isinstance(value, (bool, np.bool_)):
        raise refuse("a number")
    if isinstance(default, int):
        try:
            f = float(value)
        except (TypeError, ValueError):
            raise refuse("an integer") from None
        if not math.isfinite(f) or f != int(f):
            raise refuse("an integer")
        return int(f)
    if isinstance(default, float) or (default is None and _is_number(value)):
        try:
            return float(value)
        except (TypeError, ValueError):
            raise refuse("a number") from None
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
