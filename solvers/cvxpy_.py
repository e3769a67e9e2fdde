"""The QP through cvxpy, solved by any installed cvxpy backend (``solver`` parameter).

Formulation (on the normalised QP of :mod:`dualfem.numerics.scaling` when ``scale`` is true):

    minimize 1/2 y' P y + q' y   subject to   A y >= 0.

cvxpy's dual value of a constraint ``expr >= 0`` is >= 0 with the Lagrangian ``f - nu' expr``
(stationarity ``P y + q = A' nu``), so with the scaling undone our nodal contact force is
``mu = R nu / c`` (see :class:`dualfem.numerics.scaling.ScaledQP`), ``K x - F = B' mu``; the sign is
checked in tests/test_cvxpy.py.

cvxpy's status is reported as it is: ``optimal`` -> solved, ``optimal_inaccurate`` ->
inaccurate, ``user_limit`` -> max_iter (cvxpy's status for an iteration or time cap),
``infeasible*`` -> infeasible, ``unbounded*`` -> numerical_error (a convex QP with K positive
definite cannot be unbounded), and a ``SolverError`` raised by the backend -> numerical_error
with its message. ``eps`` is passed to the backend under its own option names (CLARABEL:
tol_gap_abs, tol_gap_rel, tol_feas; OSQP and SCS: eps_abs, eps_rel; others: not passed).
The declared ``tolerance`` of an instance depends on the backend (interior point vs ADMM).

``polish`` (default true): after the backend, :func:`dualfem.numerics.polish.active_set_polish` guesses
the active set from the backend's (x, mu), solves the equality-constrained problem on it exactly
and keeps the result only if it is consistent (mu >= 0, open gaps >= 0); ``info["polish"]`` says
what happened (how much it gains: docs/measurements.md). With polishing the instance promises
1e-8; when the polish is inconsistent a ``solved`` status is downgraded to ``inaccurate`` (the
backend's answer is then only as good as the backend's own tolerance, which the evaluator shows). On a QP
with Tresca friction the polish is the exact face polish (:mod:`dualfem.numerics.face_polish`), downgraded
the same way when it does not hold.
"""
from __future__ import annotations

import contextlib
import warnings

import numpy as np

from dualfem.core.quiet import c_stdout_to_stderr
from dualfem.errors import InputError
from dualfem.laws import conic_rows
from dualfem.numerics.coulomb import coulomb_blocks
from dualfem.numerics.coulomb_run import coulomb_solution
from dualfem.numerics.epigraph import norm_blocks, uniform_scaling
from dualfem.numerics.face_polish import polish_if_better as face_polish_if_better
from dualfem.numerics.polish import active_set_polish
from dualfem.numerics.scaling import scale
from dualfem.registry import register_solver
from dualfem.solution import Solution, Status
from dualfem.solver import Solver

#: accuracy promised per backend at default settings (relative energy-norm error of x)
BACKEND_TOLERANCE = {"CLARABEL": 1e-5, "ECOS": 1e-5, "MOSEK": 1e-5, "GUROBI": 1e-5,
                     "OSQP": 1e-3, "SCS": 1e-3, "PIQP": 1e-5, "PROXQP": 1e-3}
_DEFAULT_TOLERANCE = 1e-3

_STATUS = {
    "optimal": Status.SOLVED,
    "optimal_inaccurate": Status.INACCURATE,
    "user_limit": Status.MAX_ITER,
    "infeasible": Status.INFEASIBLE,
    "infeasible_inaccurate": Status.INFEASIBLE,
    "unbounded": Status.NUMERICAL_ERROR,
    "unbounded_inaccurate": Status.NUMERICAL_ERROR,
    "infeasible_or_unbounded": Status.NUMERICAL_ERROR,
    "solver_error": Status.NUMERICAL_ERROR,
}


def _eps_options(backend: str, eps: float) -> dict:
    if backend == "CLARABEL":
        return {"tol_gap_abs": eps, "tol_gap_rel": eps, "tol_feas": eps}
    if backend in ("OSQP", "SCS"):
        return {"eps_abs": eps, "eps_rel": eps}
    return {}


def _time_options(backend: str, time_limit: float) -> dict:
    if backend in ("CLARABEL", "OSQP"):
        return {"time_limit": time_limit}
    if backend == "SCS":
        return {"time_limit_secs": time_limit}
    return {}


def _iter_options(backend: str, max_iter: int) -> dict:
    if backend in ("CLARABEL", "OSQP"):
        return {"max_iter": max_iter}
    if backend == "SCS":
        return {"max_iters": max_iter}
    return {}


#: cvxpy backends that are first-order methods (ADMM): an instance or a variant naming one is of the
#: ``first-order`` family (:meth:`CvxpySolver.variant_family`), the others ``interior point``
FIRST_ORDER_BACKENDS = ("OSQP", "SCS", "PIQP_ADMM")


@register_solver
class CvxpySolver(Solver):
    """cvxpy modelling layer over a chosen backend (default CLARABEL)."""

    name = "cvxpy"
    family = "interior point"
    #: the bilateral law (G x = 0, mu free) as cvxpy equality rows (conic_rows), with the default backend
    #: CLARABEL only (tests/plugin_laws; the Signorini polish does not apply, so an instance with another
    #: backend accepts Signorini only: :meth:`validate`); Tresca friction as norm terms of the objective
    #: (:meth:`_setup_friction`), Coulomb by the fixed point over those (dualfem.numerics.coulomb_run), CLARABEL only
    accepts = ("signorini", "bilateral", "tresca", "coulomb")
    description = "cvxpy with a chosen backend (CLARABEL, OSQP, SCS, ... as installed)"
    requires = ("cvxpy",)
    tolerance = BACKEND_TOLERANCE["CLARABEL"]
    exact = True
    defaults = {
        "solver": "CLARABEL",
        "tol": 1e-10,             # the backend's accuracy options (see _eps_options)
        "max_iter": 10000,
        "time_limit": 600.0,      # seconds (CLARABEL, OSQP, SCS; other backends ignore it)
        "scale": True,
        "polish": True,
        "verbose": False,
        "coulomb_tol": 1e-10,     # Coulomb: relative change of the threshold that stops the fixed point
        "coulomb_max_iter": 50,   # Coulomb: most Tresca solves
    }

    renamed = {"eps": "tol"}
    ranges = {"solver": None, "scale": bool, "polish": bool,   # solver: an installed backend (validate)
              "coulomb_tol": "(0, 1)", "coulomb_max_iter": "[1, 1000]"}

    @classmethod
    def variant_family(cls, variant: str) -> str:
        """``first-order`` for a variant naming a first-order backend (:data:`FIRST_ORDER_BACKENDS`, in any
        case: ``cvxpy:OSQP``, ``cvxpy[solver=scs]``), else :attr:`family` (``interior point``)."""
        up = variant.upper()
        return "first-order" if any(b in up for b in FIRST_ORDER_BACKENDS) else cls.family

    def validate(self) -> None:
        backend = str(self.params["solver"]).upper()
        self.params["solver"] = backend
        if self.missing() is None:
            import cvxpy as cp

            installed = cp.installed_solvers()
            if backend not in installed:
                raise InputError(f"parameter 'solver' of solver 'cvxpy' must be an installed cvxpy "
                                 f"backend ({', '.join(installed)}), got {backend!r}")
        # an instance promises what its backend (and the polish) can deliver
        self.tolerance = 1e-8 if self.params["polish"] else BACKEND_TOLERANCE.get(backend, _DEFAULT_TOLERANCE)
        self.accepts = type(self).accepts if backend == "CLARABEL" else ("signorini",)
        self.family = type(self).variant_family(backend)      # an instance declares its backend's family

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        """The backend to ``min(tol, 1e-8)``, then the polish (default on): a looser backend can hand the
        polish a wrong contact set (measured: docs/measurements.md)."""
        return {"tol": min(float(tol), 1e-8)}

    @classmethod
    def backend_options(cls, params: dict) -> dict:
        """The options of the cvxpy backend named by ``solver`` (CLARABEL, OSQP, PIQP: read from the installed
        library), less those dualfem sets (accuracy, iteration cap, time limit); passed to ``Problem.solve``."""
        from dualfem.numerics.backend_options import CVXPY_READERS

        backend = str(params.get("solver", "")).upper()
        reader = CVXPY_READERS.get(backend)
        if reader is None:
            return {}
        own = {*_eps_options(backend, 1.0), *_iter_options(backend, 1), *_time_options(backend, 1.0), "verbose"}
        return {k: v for k, v in reader().items() if k not in own}

    def setup(self, qp) -> None:
        import cvxpy as cp
        import scipy.sparse as sp

        self.qp = self._qp_now = qp
        self._friction = None
        if coulomb_blocks(qp):      # built per Tresca problem of the fixed point (solve)
            return
        if norm_blocks(qp):
            self._setup_friction(qp)
            return
        self._scaled = s = scale(qp, self.params["scale"])
        y = cp.Variable(qp.n)
        P = sp.csc_matrix(0.5 * (s.P + s.P.T))
        self._eq = None
        if qp.blocks:       # further blocks: 'nonneg' rows as A y >= 0, 'zero' rows as A y == 0 (conic_rows)
            self._eq = eq = np.concatenate([np.full(m, kind == "zero") for kind, m in conic_rows(qp.constraints)])
            self._cons = [s.A[np.flatnonzero(~eq)] @ y >= 0, s.A[np.flatnonzero(eq)] @ y == 0]
        else:
            self._cons = [s.A @ y >= 0]
        self._prob = cp.Problem(cp.Minimize(0.5 * cp.quad_form(y, cp.psd_wrap(P)) + s.q @ y), self._cons)
        self._y = y

    def _setup_friction(self, qp) -> None:
        """Tresca blocks as ``sum_j rt_j ||s_j||`` with slip variables ``s == A_k y`` (their duals are the friction
        forces: cvxpy's Lagrangian ``f + d'(s - A_k y)`` gives ``P y + q = A_k' d``, so nu = d); cone blocks as in
        :meth:`setup`. The scaling shares one factor per friction node
        (:func:`dualfem.numerics.epigraph.uniform_scaling`)."""
        import cvxpy as cp
        import scipy.sparse as sp

        self._qp_now = qp
        self._scaled = s = uniform_scaling(qp, self.params["scale"])
        o = np.cumsum([0, *(b.m for b in qp.constraints)])
        y = cp.Variable(qp.n)
        objective = 0.5 * cp.quad_form(y, cp.psd_wrap(sp.csc_matrix(0.5 * (s.P + s.P.T)))) + s.q @ y
        cons, kinds = [], []
        for k, b in enumerate(qp.constraints):
            A = s.A[o[k]:o[k + 1]]
            radius = b.law.norm_term(b.weights)
            if radius is None:
                kinds.append(b.law.conic())
                cons.append(A @ y == 0 if kinds[-1] == "zero" else A @ y >= 0)
                continue
            c = b.law.components
            slip = cp.Variable(b.m)
            rt = np.asarray(radius, float) / (s.c * s.r[o[k]:o[k + 1]:c])
            norms = cp.abs(slip) if c == 1 else cp.norm(cp.reshape(slip, (b.m // c, c), order="C"), 2, axis=1)
            objective = objective + rt @ norms
            kinds.append("slip")
            cons.append(slip == A @ y)
        self._prob = cp.Problem(cp.Minimize(objective), cons)
        self._cons, self._y, self._friction, self._eq = cons, y, kinds, None

    def _friction_multipliers(self) -> np.ndarray | None:
        """The scaled multipliers of every block from the duals (``zero`` rows: cvxpy's ``-d``, see _stacked)."""
        parts = []
        for kind, con in zip(self._friction, self._cons):
            d = con.dual_value
            if d is None:
                return None
            d = np.asarray(d, float).ravel()
            parts.append(-d if kind == "zero" else d)
        return np.concatenate(parts)

    def solve(self) -> Solution:
        if coulomb_blocks(self.qp):
            def tresca(tq):
                self._setup_friction(tq)
                return self._solve_built()

            return coulomb_solution(self, tresca, "cvxpy")
        return self._solve_built()

    def _solve_built(self) -> Solution:
        import cvxpy as cp

        backend = self.params["solver"]
        opts = {**_eps_options(backend, self.params["tol"]), **_iter_options(backend, self.params["max_iter"]),
                **_time_options(backend, float(self.params["time_limit"])),
                **{k: v for k, v in self.params.items() if k not in self.defaults}}     # the backend's own options
        try:
            quiet = contextlib.nullcontext() if self.params["verbose"] else c_stdout_to_stderr()
            with warnings.catch_warnings(), quiet:
                # cvxpy warns "Solution may be inaccurate": the status says it already
                warnings.simplefilter("ignore", UserWarning)
                self._prob.solve(solver=backend, verbose=bool(self.params["verbose"]), **opts)
        except cp.error.SolverError as exc:
            return Solution(solver=self.name, status=Status.NUMERICAL_ERROR,
                            message=f"cvxpy/{backend}: SolverError: {exc}", info={"backend": backend})
        text = str(self._prob.status)
        status = _STATUS.get(text, Status.ERROR)
        yv, nu = self._y.value, self._cons[0].dual_value
        if self._eq is not None:
            nu = _stacked(self._eq, self._cons)
        elif self._friction is not None:
            nu = self._friction_multipliers()
        stats = self._prob.solver_stats
        iters = {"backend": int(stats.num_iters)} if stats is not None and stats.num_iters is not None else {}
        info = {"backend": backend, "cvxpy_status": text,
                "backend_solve_time_s": getattr(stats, "solve_time", None)}
        if yv is None or nu is None:
            return Solution(solver=self.name, status=status if status != Status.SOLVED else Status.ERROR,
                            iterations=iters, message=f"cvxpy/{backend}: {text} (no solution returned)", info=info)
        x, mu = self._scaled.unscale(np.asarray(yv, float).ravel(), np.asarray(nu, float).ravel())
        msg = f"cvxpy/{backend}: {text}"
        if self.params["polish"] and status in (Status.SOLVED, Status.INACCURATE) and self._friction is not None:
            x, mu, pinfo = face_polish_if_better(self._qp_now, x, mu)
            info["polish"] = {"applied": pinfo.pop("polished"), **pinfo}
            if not info["polish"]["applied"]:
                status = Status.INACCURATE if status == Status.SOLVED else status
                msg += "; exact face polish did not hold: unpolished backend answer kept"
            else:
                msg += f"; polished on its exact face ({pinfo['face_steps']} Newton step(s))"
        elif self.params["polish"] and status in (Status.SOLVED, Status.INACCURATE) and self._eq is None:

            try:
                pol = active_set_polish(self._qp_now, x, mu)
            except Exception as exc:  # noqa: BLE001 - the polish is optional; say why it failed
                pol = None
                info["polish_error"] = f"{type(exc).__name__}: {exc}"
            if pol is not None:
                x, mu, pinfo = pol
                info["polish"] = {"applied": True, **pinfo}
                msg += f"; polished on {pinfo['n_active']} contact nodes (x moved {pinfo['x_change_energy']:.1e})"
            else:
                info["polish"] = {"applied": False}
                if status == Status.SOLVED:
                    status = Status.INACCURATE
                msg += "; active-set polish inconsistent: unpolished backend answer kept"
        return Solution(solver=self.name, status=status, x=x, multipliers=mu, iterations=iters,
                        message=msg, info=info)


def _stacked(eq: np.ndarray, cons: list) -> np.ndarray | None:
    """The scaled multipliers of every row in block order from cvxpy's duals of ``A_in y >= 0`` (>= 0) and of
    ``A_eq y == 0`` (cvxpy: P y + q = A_in' d_in - A_eq' d_eq, so nu_eq = -d_eq); None when cvxpy gave none."""
    d_in, d_eq = cons[0].dual_value, cons[1].dual_value
    if d_eq is None or ((~eq).any() and d_in is None):
        return None
    nu = np.zeros(eq.size)
    nu[~eq] = np.asarray(d_in, float).ravel() if (~eq).any() else 0.0
    nu[eq] = -np.asarray(d_eq, float).ravel()
    return nu
