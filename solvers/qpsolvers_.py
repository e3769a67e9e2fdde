"""Every backend of qpsolvers as a dualfem solver ``qp_<backend>`` (qp_proxqp, qp_piqp, ...).

The QP is normalised first, exactly as for OSQP (:func:`dualfem.numerics.scaling.scale`: unit diagonal,
unit load, unit constraint rows), and handed to ``qpsolvers.solve_problem`` as

    min 1/2 y'Py + q'y   s.t.   G y <= h,   G = -A (the scaled B),  h = 0.

qpsolvers' multiplier ``z >= 0`` of ``G y <= h`` satisfies ``P y + q + G'z = 0``, i.e.
``P y + q = A'z``: in the scaled units ``z`` is our contact force, ``mu = c R z`` after
:meth:`~dualfem.numerics.scaling.ScaledQP.unscale`. Status: ``Solution.found`` (the backend's own
success test) gives ``solved``; otherwise ``inaccurate`` with the iterate, or
``numerical_error`` without one.

The list of backends is qpsolvers' own: the modules of the installed ``qpsolvers.solvers``
package (read from disk, without importing the backends), plus the table below when qpsolvers
is absent. A backend whose Python module is missing is listed as NOT INSTALLED with its install
hint. ``_BACKENDS`` maps each known backend to its module, its pip package, whether it works on
dense matrices (those skip QPs with more than ``max_n`` unknowns), the option names that target
an accuracy, the iteration cap and the time limit (from qpsolvers' docstrings), and the
tolerance measured on the paper's scenes f1/f2/f3, N = 16 and 32, delta = 1e-1/1e-5/1e-9 (see
the class docstrings; ``notes`` says what was seen).

Each backend's declared tolerance is above the worst error measured on those scenes (the numbers:
docs/measurements.md); the jax backends (qpax, jaxopt_osqp) declare 1e-2, not measured over the full set.

**What it takes to meet a tolerance** (docs/solvers_tolerances.md): the interior-point backends
(clarabel, piqp, sip) stop at delta = 1e-9 with x 1e-6..1e-5 off and multipliers 1e-4..1e-2 off,
whatever their tolerances (f2, N = 16..64); ``polish = true`` (dualfem's active-set polish, kept only
when consistent and better, ``info["polished"]``) brings them to rounding once the backend stopped at
1e-8 or tighter. :meth:`QpsolversSolver.tolerance_params` asks every backend for ``min(tier / 100,
1e-8)`` with the polish. ``polish`` is off by default: ``qp_<backend>`` alone is the backend's answer.
A backend's own options pass through as parameters where its option list can be read from the
installed library (clarabel, osqp, piqp: :meth:`QpsolversSolver.backend_options`).

**Friction** (the backends of :data:`BILATERAL`): 2D Tresca as the linear epigraph of
:mod:`dualfem.numerics.epigraph` (boxes: two linear rows per node); 2D Coulomb by the fixed point
``g <- mu_f lambda`` over those Tresca solves (:mod:`dualfem.numerics.coulomb_run`, parameters ``coulomb_tol``,
``coulomb_max_iter``): ``iterations["coulomb"]`` Tresca solves, ``info["coulomb"]`` the changes and the
observed contraction, status ``max_iter`` (never ``solved``) when it stalls or reaches its cap. 3D friction
(discs: second-order cones) is skipped with the reason, and so is friction for the backends that need a
positive definite P (:data:`NEEDS_DEFINITE_P`: the epigraph variables have none).
"""
from __future__ import annotations

import importlib.util
import os
import pkgutil
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dualfem.core.quiet import c_stdout_to_stderr
from dualfem.laws import conic_rows
from dualfem.numerics.coulomb import coulomb_blocks
from dualfem.numerics.coulomb_run import coulomb_solution
from dualfem.numerics.epigraph import epigraph, norm_blocks, not_linear
from dualfem.numerics.face_polish import polish_if_better as face_polish_if_better
from dualfem.numerics.polish import polish_if_better
from dualfem.numerics.scaling import scale
from dualfem.registry import register_solver
from dualfem.solution import Solution, Status
from dualfem.solver import Solver

#: default size above which dense backends are skipped (a dense n x n Hessian: 8 n^2 bytes and
#: O(n^3) factorizations; at n = 3000 that is 72 MB and seconds per factorization)
DENSE_MAX_N = 3000
#: backends that refuse a QP without constraints (SCS: "m must be a positive integer"): skipped with the reason
NEEDS_A_CONSTRAINT = ("scs",)
#: backends that need a positive definite P (qpsolvers' ProblemError "matrix P is not positive definite"): the
#: epigraph of a frictional QP has a zero block for its variables t, so they skip friction with the reason
NEEDS_DEFINITE_P = ("ecos", "quadprog")


def _tols(*names: str) -> Callable[[float], dict]:
    return lambda tol: {k: tol for k in names}


@dataclass(frozen=True)
class Backend:
    """What dualfem knows about one qpsolvers backend."""

    module: str                       # importable module the backend needs
    pip: str                          # what to pip install (besides qpsolvers)
    dense: bool = False               # works on dense matrices: skipped above max_n
    accuracy: Callable[[float], dict] = field(default=lambda tol: {})
    max_iter: str | None = None       # option name of the iteration cap
    time_limit: str | None = None     # option name of the time limit (seconds)
    tolerance: float = 1e-3           # declared (measured) relative accuracy, see module doc
    notes: str = ""
    extra: Callable[[], dict] = field(default=lambda: {})
    family: str = "interior point"    # Solver.family of its qp_ solver (dualfem.core.solver.SOLVER_FAMILIES)


_BACKENDS: dict[str, Backend] = {
    "clarabel": Backend("clarabel", "clarabel", accuracy=_tols("tol_gap_abs", "tol_gap_rel", "tol_feas"),
                        max_iter="max_iter", time_limit="time_limit", tolerance=1e-4),
    "copt": Backend("coptpy", "coptpy", accuracy=_tols("FeasTol", "DualTol"), time_limit="TimeLimit",
                    notes="commercial"),
    "cvxopt": Backend("cvxopt", "cvxopt", dense=True, accuracy=lambda t: {"abstol": t, "reltol": t, "feastol": t},
                      max_iter="maxiters", tolerance=1e-4),
    "daqp": Backend("daqp", "daqp", dense=True, accuracy=_tols("primal_tol", "dual_tol"),
                    max_iter="iter_limit", time_limit="time_limit", tolerance=1e-9, family="active set"),
    "ecos": Backend("ecos", "ecos", dense=True, accuracy=_tols("abstol", "reltol", "feastol"),
                    max_iter="max_iters", tolerance=1e-2,
                    notes="loose: KKT error up to 6.5e-3 when it claims success at delta = 1e-9"),
    "gurobi": Backend("gurobipy", "gurobipy", accuracy=_tols("FeasibilityTol", "OptimalityTol"),
                      time_limit="TimeLimit", notes="commercial"),
    "highs": Backend("highspy", "highspy", accuracy=_tols("primal_feasibility_tolerance", "dual_feasibility_tolerance"),
                     time_limit="time_limit", tolerance=1e-2,
                     notes="loose: x error 1e-4..1.1e-3 whatever its feasibility tolerances", family="active set"),
    "hpipm": Backend("hpipm_python", "hpipm_python", dense=True,
                     accuracy=_tols("tol_stat", "tol_eq", "tol_ineq", "tol_comp"), max_iter="iter_max"),
    "jaxopt_osqp": Backend("jaxopt", "jaxopt", dense=True, accuracy=_tols("tol"),
                           tolerance=1e-2, notes="pulls jax (run in float64); measured: x error 4e-13 but "
                           "'not found' on f1, delta = 0.1", family="first-order"),
    "kvxopt": Backend("kvxopt", "kvxopt", dense=True, accuracy=_tols("abstol", "reltol", "feastol"),
                      max_iter="maxiters"),
    "mosek": Backend("mosek", "mosek", notes="commercial"),
    "nppro": Backend("nppro", "nppro", dense=True, max_iter="MaxIter", family="active set"),
    "osqp": Backend("osqp", "osqp", accuracy=_tols("eps_abs", "eps_rel"), max_iter="max_iter",
                    time_limit="time_limit", tolerance=1e-6,     # 9.2e-9 on thin_defect; certificate 4.9e-7
                    family="first-order"),                        # on the membrane of docs/plugins.md
    "pdhcg": Backend("pdhcg", "pdhcg", accuracy=_tols("FeasibilityTol", "OptimalityTol"),
                     max_iter="IterationLimit", time_limit="TimeLimit", family="first-order"),
    "piqp": Backend("piqp", "piqp", accuracy=_tols("eps_abs", "eps_rel", "eps_duality_gap_abs", "eps_duality_gap_rel"),
                    max_iter="max_iter", tolerance=1e-4),
    "proxqp": Backend("proxsuite", "proxsuite", accuracy=lambda t: {"eps_abs": t, "eps_rel": 0.0},
                      max_iter="max_iter", tolerance=1e-6, family="first-order"),
    "pyqpmad": Backend("pyqpmad", "pyqpmad", dense=True, accuracy=_tols("tolerance"), max_iter="max_iter",
                       tolerance=1e-9, family="active set"),
    "qpalm": Backend("qpalm", "qpalm", accuracy=_tols("eps_abs", "eps_rel"), max_iter="max_iter",
                     time_limit="time_limit", tolerance=1e-6, family="first-order"),
    "qpax": Backend("qpax", "qpax", dense=True, accuracy=_tols("solver_tol"),
                    tolerance=1e-2, notes="pulls jax (run in float64); its own iteration cap; measured: x "
                    "error 1e-14 but 'not found' on f1, delta = 0.1"),
    "qpoases": Backend("qpoases", "qpoases", dense=True, accuracy=_tols("terminationTolerance"), family="active set"),
    "qpswift": Backend("qpSWIFT", "qpSWIFT", dense=True, accuracy=_tols("ABSTOL", "RELTOL"), max_iter="MAXITER"),
    "qtqp": Backend("qtqp", "qtqp", accuracy=_tols("tol_feas", "tol_gap_abs", "tol_gap_rel"), max_iter="max_iter",
                    tolerance=1e-4),
    "quadprog": Backend("quadprog", "quadprog", dense=True, tolerance=1e-9, family="active set"),
    "scs": Backend("scs", "scs", accuracy=_tols("eps_abs", "eps_rel"), max_iter="max_iters",
                   time_limit="time_limit_secs", tolerance=1e-8, family="first-order"),
    "sip": Backend("sip_qp_python", "sip_qp_python", accuracy=_tols("eps_abs", "eps_rel"),
                   max_iter="max_iterations", time_limit="time_limit", tolerance=1e-5),
}


#: backends whose tolerance was measured (installed here; f1/f2/f3, N = 16/32, delta = 1e-1/1e-5/1e-9)
MEASURED = ("clarabel", "cvxopt", "daqp", "ecos", "highs", "jaxopt_osqp", "osqp", "piqp", "proxqp", "pyqpmad",
            "qpalm", "qpax", "qtqp", "quadprog", "scs", "sip")


def known_backends() -> list[str]:
    """qpsolvers' backend names: its ``solvers`` modules on disk (no import), or the table."""
    names = set(_BACKENDS)
    spec = importlib.util.find_spec("qpsolvers")
    if spec is not None and spec.submodule_search_locations:
        for loc in spec.submodule_search_locations:
            for info in pkgutil.iter_modules([os.path.join(loc, "solvers")]):
                if info.name.endswith("_") and not info.name.startswith("_"):
                    names.add(info.name[:-1])
    return sorted(names)


class QpsolversSolver(Solver):
    """One qpsolvers backend on the normalised QP (subclassed once per backend below)."""

    backend: str = ""
    requires = ("qpsolvers",)
    extra = "qp"
    defaults = {"tol": 1e-9, "max_iter": 100000, "time_limit": 600.0, "verbose": False,
                "scale": True, "max_n": 0, "polish": False,
                "coulomb_tol": 1e-8,      # Coulomb: relative change of the threshold that stops the fixed point
                "coulomb_max_iter": 50}   # Coulomb: most Tresca solves

    ranges = {"scale": bool, "max_n": "[0, inf)", "polish": bool,     # max_n = 0: the backend's default
              "coulomb_tol": "(0, 1)", "coulomb_max_iter": "[1, 1000]"}

    @classmethod
    def info(cls) -> Backend:
        return _BACKENDS.get(cls.backend, Backend(cls.backend, cls.backend))

    @classmethod
    def missing(cls) -> str | None:
        b = cls.info()
        for mod in ("qpsolvers", b.module):
            if importlib.util.find_spec(mod) is None:
                hint = ("pip install 'dualfem[qp]'" if cls.backend in QP_EXTRA
                        else f"pip install qpsolvers {b.pip}")
                return f"solver {cls.name!r} needs the Python module {mod!r}: {hint}"
        return None

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        """The backend to ``min(tol / 100, 1e-8)``, then the polish (measured: see the module docstring)."""
        return {"tol": min(float(tol) * 1e-2, 1e-8), "polish": True}

    @classmethod
    def backend_options(cls, params: dict) -> dict:
        """The backend library's own options, where they can be read from it (clarabel, osqp, piqp);
        the names dualfem sets itself (its accuracy, iteration cap and time limit options) excluded."""
        from dualfem.numerics.backend_options import QPSOLVERS_READERS

        reader = QPSOLVERS_READERS.get(cls.backend)
        if reader is None:
            return {}
        b = cls.info()
        own = {*b.accuracy(1.0), b.max_iter, b.time_limit, "verbose"}
        return {k: v for k, v in reader().items() if k not in own}

    def _max_n(self) -> int:
        if self.params["max_n"] > 0:
            return int(self.params["max_n"])
        return DENSE_MAX_N if self.info().dense else 10 ** 9

    def skip(self, qp) -> str | None:
        if getattr(qp, "blocks", ()) and not_linear(qp):
            return not_linear(qp)
        if self.backend in NEEDS_DEFINITE_P and getattr(qp, "blocks", ()) and (norm_blocks(qp) or coulomb_blocks(qp)):
            return (f"{self.backend} needs a positive definite P; friction's epigraph variables (one per friction "
                    f"node, dualfem.numerics.epigraph) have none")
        if qp.n > self._max_n():
            return (f"{self.backend} works on dense matrices: n = {qp.n} unknowns > max_n = {self._max_n()} "
                    f"(set -p max_n=... to try anyway)")
        import qpsolvers

        if self.backend not in qpsolvers.available_solvers:
            return f"qpsolvers {qpsolvers.__version__} could not load its backend {self.backend!r}"
        return None

    def settings(self) -> dict[str, Any]:
        """Backend options for the parameters (accuracy, iteration cap, time limit)."""
        b, p = self.info(), self.params
        out = dict(b.accuracy(float(p["tol"])))
        if b.max_iter:
            out[b.max_iter] = int(p["max_iter"])
        if b.time_limit:
            out[b.time_limit] = float(p["time_limit"])
        out.update(b.extra())
        out.update({k: v for k, v in p.items() if k not in self.defaults})     # the backend's own options
        return out

    def setup(self, qp) -> None:
        if self.info().module in ("jax", "jaxopt", "qpax"):
            import jax

            jax.config.update("jax_enable_x64", True)    # float32 (jax's default) stops at ~1e-6
        self.qp = qp
        if not coulomb_blocks(qp):      # Coulomb: built per Tresca problem of the fixed point (solve)
            self._build(qp)

    def _build(self, qp) -> None:
        """The qpsolvers Problem of ``qp`` (``self._problem``; ``self._epi`` the epigraph of a frictional QP)."""
        import qpsolvers

        self._qp_now = qp
        self._epi = None
        if norm_blocks(qp):       # 2D friction: the linear epigraph over [y, t] (dualfem.numerics.epigraph)
            self._epi = e = epigraph(qp, self.params["scale"])
            Pq, Aall, q, cones = e.P, e.A, e.q, e.cones
        else:
            self._scaled = s = scale(qp, self.params["scale"])
            Pq, Aall, q, cones = s.P, s.A, s.q, conic_rows(qp.constraints)
        G = -Aall.tocsc()
        P = (0.5 * (Pq + Pq.T)).tocsc()     # exactly symmetric (some backends test it)
        if self.info().dense:
            P, G = P.toarray(), G.toarray()
        self._eq = None
        if qp.blocks:       # further blocks: 'nonneg' rows as G x <= 0, 'zero' rows as A x = 0 (conic_rows)
            self._eq = eq = np.concatenate([np.full(m, kind == "zero") for kind, m in cones])
            G, A = G[np.flatnonzero(~eq)], Aall.tocsc()[np.flatnonzero(eq)]
            if self.info().dense:
                A = A.toarray()
            self._problem = qpsolvers.Problem(P, q, G if (~eq).any() else None,
                                              np.zeros(G.shape[0]) if (~eq).any() else None,
                                              A if eq.any() else None, np.zeros(A.shape[0]) if eq.any() else None)
            return
        # no constraint (m = 0, an uncracked body): quadprog takes no G at all (it fails on a 0-row G)
        self._problem = qpsolvers.Problem(P, s.q) if qp.m == 0 and self.backend == "quadprog" else \
            qpsolvers.Problem(P, s.q, G, np.zeros(qp.m))

    def solve(self) -> Solution:
        if self.qp.m == 0 and self.backend in NEEDS_A_CONSTRAINT:
            return Solution(solver=self.name, status=Status.SKIPPED,
                            message=f"{self.backend} needs at least one constraint; this QP has none (m = 0)")
        if coulomb_blocks(self.qp):
            return self._coulomb()
        return self._run()

    def _coulomb(self) -> Solution:
        """2D Coulomb by the fixed point over this backend's Tresca solves (:mod:`dualfem.numerics.coulomb_run`):
        the iteration counts and the observed contraction in ``iterations`` / ``info["coulomb"]``; ``max_iter``
        (never ``solved``) when the fixed point stalls or reaches ``coulomb_max_iter``."""
        def tresca(tq):
            self._build(tq)
            return self._run()

        return coulomb_solution(self, tresca, self.name, prefix=self.backend)

    def _run(self) -> Solution:
        """The backend on the Problem of the last :meth:`_build`, unscaled (and polished on request)."""
        import qpsolvers

        qp = self._qp_now
        with warnings.catch_warnings(), c_stdout_to_stderr():
            warnings.simplefilter("ignore")
            res = qpsolvers.solve_problem(self._problem, solver=self.backend,
                                          verbose=bool(self.params["verbose"]), **self.settings())
        x = None if res.x is None else np.asarray(res.x, float)
        nz = qp.n if self._epi is None else self._epi.P.shape[0]
        ok = x is not None and x.shape == (nz,) and np.all(np.isfinite(x))
        z = res.z if res.z is not None and np.shape(res.z) == (qp.m,) else np.zeros(qp.m)
        if self._eq is not None:
            z = _stacked(self._eq, res)
        text = _status_text(res)
        if not ok:
            return Solution(solver=self.name, status=Status.NUMERICAL_ERROR,
                            message=f"{self.backend}: no finite solution returned ({text})")
        unscale = self._epi.unscale if self._epi is not None else self._scaled.unscale
        x, mu = unscale(x, np.nan_to_num(np.asarray(z, float)))
        status = Status.SOLVED if res.found else Status.INACCURATE
        msg = f"{self.backend}: {text}" if res.found else f"{self.backend}: not found ({text})"
        iters = _iterations(res)
        info = {"backend_solve_time_s": getattr(res, "solve_time", None),
                "backend_build_time_s": getattr(res, "build_time", None)}
        if self.params["polish"] and status == Status.SOLVED and self._epi is not None:   # friction's exact face
            x, mu, pinfo = face_polish_if_better(qp, x, mu)
            info.update(pinfo)
            msg += "; polished on its exact face" if pinfo["polished"] else "; face polish refused"
        elif self.params["polish"] and status == Status.SOLVED and self._eq is None:   # the polish is Signorini's
            x, mu, pinfo = polish_if_better(qp, x, mu)
            info.update(pinfo)
            msg += "; polished" if pinfo["polished"] else "; polish refused (inconsistent or no better)"
        return Solution(solver=self.name, status=status, x=x, multipliers=mu,
                        iterations=iters, message=msg, info=info)


def _stacked(eq: np.ndarray, res) -> np.ndarray:
    """The scaled multipliers of every row in block order: ``z`` of the inequality rows, ``-y`` of the equality
    rows (qpsolvers: P x + q + G'z + A'y = 0, ours: P x + q = A_all' nu); zeros where the backend gave none."""
    nu = np.zeros(eq.size)
    z, y = res.z, res.y
    if z is not None and np.shape(z) == ((~eq).sum(),):
        nu[~eq] = z
    if y is not None and np.shape(y) == (eq.sum(),):
        nu[eq] = -np.asarray(y, float)
    return nu


def _status_text(res) -> str:
    """The backend's own status word, when qpsolvers keeps it in ``extras``."""
    ex = getattr(res, "extras", None) or {}
    for key in ("status", "info"):
        v = ex.get(key)
        if v is None:
            continue
        st = getattr(v, "status", None)
        if st is None and isinstance(v, dict):
            st = v.get("status") or v.get("exitFlag")
        return str(st if st is not None else v)[:120]
    return "found" if res.found else "failure"


def _iterations(res) -> dict[str, int]:
    ex = getattr(res, "extras", None) or {}
    for key in ("iter", "iterations", "num_iter", "iter_count"):
        v = ex.get(key)
        if isinstance(v, (int, np.integer)):
            return {"backend": int(v)}
    info = ex.get("info")
    for attr in ("iter", "iter_count", "iterations"):
        v = getattr(info, attr, None) if info is not None else None
        if isinstance(v, (int, np.integer)):
            return {"backend": int(v)}
    return {}


#: backends installed by ``pip install 'dualfem[qp]'`` (wheels for Linux x86-64, no jax)
QP_EXTRA = ("clarabel", "cvxopt", "daqp", "ecos", "highs", "osqp", "piqp", "proxqp", "pyqpmad",
            "qpalm", "quadprog", "scs", "sip")


#: backends that accept the bilateral law (G x = 0, mu free) as qpsolvers' equality rows A x = 0: those of
#: ``dualfem[qp]`` that tests/plugin_laws solves; not pyqpmad (its multipliers with equality rows are wrong:
#: stationarity 0.97, demoted by the evaluator), not the backends the suite cannot install (untested)
BILATERAL = tuple(b for b in QP_EXTRA if b != "pyqpmad")


def _make(backend: str) -> type[QpsolversSolver]:
    b = _BACKENDS.get(backend, Backend(backend, backend))
    kind = "dense" if b.dense else "sparse"
    lim = "time limit" if b.time_limit else "no time limit"
    notes = [n for n in (b.notes, "" if backend in MEASURED else "tolerance not measured") if n]
    desc = f"{backend} via qpsolvers ({kind}; normalised QP; {lim}{''.join('; ' + n for n in notes)})"
    cls = type(f"Qp_{backend}", (QpsolversSolver,),
               {"name": f"qp_{backend}", "backend": backend, "description": desc, "tolerance": b.tolerance,
                "family": b.family if backend in _BACKENDS else "other",
                "accepts": ("signorini", "bilateral", "tresca", "coulomb") if backend in BILATERAL else ("signorini",),
                "__doc__": f"qpsolvers backend {backend!r}; declared tolerance {b.tolerance:g}. {b.notes}",
                "__module__": __name__})
    return register_solver(cls)


for _name in known_backends():
    globals()[f"Qp_{_name}"] = _make(_name)
