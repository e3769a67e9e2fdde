"""OSQP (ADMM, first order) on ``min 1/2 x'Kx - F'x s.t. 0 <= Bx <= inf``.

OSQP's multiplier y of ``l <= Ax <= u`` is <= 0 at an active lower bound, so our nodal contact
force is ``mu = -y``. Only the upper triangle of K is passed. With ``scale=True`` (default) the QP is
normalised first (:mod:`dualfem.numerics.scaling`). ADMM is accurate to about ``eps_rel`` in the
residuals, not in x (osqp issue 364); the evaluator reports it either way.

**What it takes to meet a tolerance** (docs/solvers_tolerances.md): :meth:`OSQPSolver.tolerance_params`
= ``{"tol": tier, "polish_refine_iter": 20}``: OSQP's polishing with its default 3 refinement steps does
not reach the tier 1e-9, with 20 it does (measured: docs/measurements.md, ``solvers/osqp_.py``);
the default stays OSQP's 3 (enough for the declared tolerance 1e-3). Without a successful polish,
ADMM's answer is only as good as eps; the certificate says so.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.core.quiet import c_stdout_to_stderr
from dualfem.laws import upper_bounds
from dualfem.numerics.coulomb import coulomb_blocks
from dualfem.numerics.coulomb_run import coulomb_solution
from dualfem.numerics.epigraph import epigraph, norm_blocks, not_linear
from dualfem.numerics.scaling import scale
from dualfem.registry import register_solver
from dualfem.solution import Solution, Status
from dualfem.solver import Solver

_STATUS = {
    "solved": Status.SOLVED,
    "solved inaccurate": Status.INACCURATE,
    "maximum iterations reached": Status.MAX_ITER,
    "run time limit reached": Status.TIME_LIMIT,
    "primal infeasible": Status.INFEASIBLE,
    "primal infeasible inaccurate": Status.INFEASIBLE,
    "dual infeasible": Status.NUMERICAL_ERROR,
    "dual infeasible inaccurate": Status.NUMERICAL_ERROR,
    "problem non convex": Status.NUMERICAL_ERROR,
}


@register_solver
class OSQPSolver(Solver):
    """OSQP with tolerances, iteration cap, polishing and time limit exposed."""

    name = "osqp"
    family = "first-order"
    #: the bilateral law (G x = 0, mu free) as rows with l = u = 0 (upper_bounds; tested in tests/plugin_laws);
    #: Tresca friction in 2D as the linear epigraph of dualfem.numerics.epigraph (3D discs: skipped, :meth:`skip`);
    #: Coulomb in 2D by the fixed point over those Tresca solves (dualfem.numerics.coulomb_run)
    accepts = ("signorini", "bilateral", "tresca", "coulomb")
    description = "OSQP 1.x (ADMM) via its Python interface"
    requires = ("osqp",)
    tolerance = 1e-3
    defaults = {
        "tol": 1e-9,              # OSQP's eps_abs = eps_rel (on the normalised QP)
        "max_iter": 200000,
        "polish": True,           # OSQP's polishing
        "polish_refine_iter": 3,  # OSQP's refinement steps of the polished solution (tiers: 20)
        "scaling": 10,
        "adaptive_rho": True,
        "time_limit": 600.0,      # seconds
        "verbose": False,
        "scale": True,
        "coulomb_tol": 1e-8,      # Coulomb: relative change of the threshold that stops the fixed point
        "coulomb_max_iter": 50,   # Coulomb: most Tresca solves
    }
    renamed = {"eps_abs": "tol", "eps_rel": "tol", "polishing": "polish"}
    ranges = {"polish": bool, "polish_refine_iter": "[0, 1000]", "scaling": "[0, 100]", "adaptive_rho": bool,
              "scale": bool, "coulomb_tol": "(0, 1)", "coulomb_max_iter": "[1, 1000]"}   # scaling: OSQP's iterations

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        """eps = the tier, and 20 refinement steps of the polish (measured: docs/measurements.md)."""
        return {"tol": tol, "polish_refine_iter": 20}

    @classmethod
    def backend_options(cls, params: dict) -> dict:
        """OSQP's own settings (``rho``, ``sigma``, ``alpha``, ``polish_refine_iter``, ...), read from the
        installed osqp; passed to ``OSQP.setup`` as given."""
        from dualfem.numerics.backend_options import osqp_options

        return osqp_options()

    def skip(self, qp) -> str | None:
        return not_linear(qp)

    def setup(self, qp) -> None:
        self.qp = qp
        if not coulomb_blocks(qp):      # Coulomb: built per Tresca problem of the fixed point (solve)
            self._build(qp)

    def _build(self, qp) -> None:
        import osqp

        settings = {k: v for k, v in self.params.items()
                    if k not in ("scale", "tol", "polish", "coulomb_tol", "coulomb_max_iter")}
        settings.update(eps_abs=self.params["tol"], eps_rel=self.params["tol"], polishing=self.params["polish"])
        self._solver = osqp.OSQP()
        self._epi = None
        if norm_blocks(qp):         # 2D friction: the linear epigraph over [y, t] (dualfem.numerics.epigraph)
            self._epi = e = epigraph(qp, self.params["scale"])
            P, q, A = e.P, e.q, e.A
            u = np.concatenate([np.full(m, np.inf if kind == "nonneg" else 0.0) for kind, m in e.cones])
        else:
            self._scaled = s = scale(qp, self.params["scale"])
            P, q, A, u = s.P, s.q, s.A, upper_bounds(qp.constraints)
        with c_stdout_to_stderr():
            self._solver.setup(P=sp.triu(P, format="csc"), q=q, A=A.tocsc(), l=np.zeros(A.shape[0]), u=u,
                               **settings)

    def solve(self) -> Solution:
        if coulomb_blocks(self.qp):
            def tresca(tq):
                self._build(tq)
                return self._run()

            return coulomb_solution(self, tresca, "osqp")
        return self._run()

    def _run(self) -> Solution:
        with c_stdout_to_stderr():
            res = self._solver.solve(raise_error=False) if _accepts_raise(self._solver) else self._solver.solve()
        text = str(res.info.status).lower()
        status = _STATUS.get(text, Status.ERROR)
        ok = res.x is not None and np.all(np.isfinite(res.x))
        unscale = self._epi.unscale if self._epi is not None else self._scaled.unscale
        x, mu = unscale(np.array(res.x), -np.array(res.y)) if ok else (None, None)
        return Solution(
            solver=self.name, status=status if ok or status != Status.SOLVED else Status.NUMERICAL_ERROR,
            x=x, multipliers=mu,
            iterations={"admm": int(res.info.iter)}, message=f"osqp: {res.info.status}",
            info={"obj_val": float(res.info.obj_val), "rho_updates": int(res.info.rho_updates)},
        )


def _accepts_raise(solver) -> bool:
    import inspect

    try:
        return "raise_error" in inspect.signature(solver.solve).parameters
    except (TypeError, ValueError):
        return False
