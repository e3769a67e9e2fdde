"""Clarabel (interior point) on ``min 1/2 x'Kx - F'x s.t. -Bx + s = 0, s >= 0``.

**What it takes to meet a tolerance** (docs/solvers_tolerances.md): Clarabel's own tolerances
(``tol`` = tol_gap_abs = tol_gap_rel = tol_feas) do not bound the certified error at small delta; the
active-set ``polish`` removes that error once the interior point stops at ``tol <= 1e-8`` (looser, the
contact set it hands over can be wrong and the polish is refused; measured: docs/measurements.md,
``solvers/clarabel_.py``). Hence ``polish`` is on by default and :meth:`ClarabelSolver.tolerance_params`
asks for ``tol = 1e-8`` with the polish at every tier.

Clarabel's KKT condition is ``Px + q + A'z = 0`` with ``z >= 0``; with ``A = -B`` and
``q = -F`` this is ``Kx - F = B'z``, so our nodal contact force is ``mu = z``. Tresca friction: the conic
program of :mod:`dualfem.numerics.epigraph` (epigraph variables t_j >= ||s_j||, second-order cones in 3D, two
linear rows per node in 2D, ``+ sum_j r_j t_j`` in the objective), the friction forces from the cones' duals,
and the polish is the exact face polish of :mod:`dualfem.numerics.face_polish` (kept only if it helps).
Only the upper triangle of K is passed. Clarabel's own residuals are not trusted (Clarabel.cpp issue 36): the
evaluator recomputes them.

With ``scale=True`` (default) the QP is normalised first (:mod:`dualfem.numerics.scaling`). The declared
tolerance 1e-5 is what an unpolished answer is worth (its accuracy limit: docs/measurements.md).
``polish=True`` (the default; it is dualfem's, not part of Clarabel: ``polish=false`` gives Clarabel's
own answer, as the reference solve does) re-solves the KKT system exactly on Clarabel's contact set and
keeps it when its KKT error is smaller, like OSQP's polishing (``info["polished"]`` says which).
Clarabel's own settings pass through as parameters (:meth:`ClarabelSolver.backend_options`).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.errors import InputError
from dualfem.laws import conic_rows
from dualfem.numerics.coulomb import coulomb_blocks
from dualfem.numerics.coulomb_run import coulomb_solution
from dualfem.numerics.epigraph import epigraph, norm_blocks
from dualfem.numerics.face_polish import polish_if_better as face_polish_if_better
from dualfem.numerics.polish import polish_if_better
from dualfem.numerics.scaling import scale
from dualfem.registry import register_solver
from dualfem.solution import Solution, Status
from dualfem.solver import Solver

_STATUS = {
    "Solved": Status.SOLVED,
    "AlmostSolved": Status.INACCURATE,
    "MaxIterations": Status.MAX_ITER,
    "MaxTime": Status.TIME_LIMIT,
    "PrimalInfeasible": Status.INFEASIBLE,
    "AlmostPrimalInfeasible": Status.INFEASIBLE,
    "DualInfeasible": Status.NUMERICAL_ERROR,
    "AlmostDualInfeasible": Status.NUMERICAL_ERROR,
    "NumericalError": Status.NUMERICAL_ERROR,
    "InsufficientProgress": Status.STAGNATION,
}


@register_solver
class ClarabelSolver(Solver):
    """Clarabel with its gap/feasibility tolerances, iteration cap and time limit exposed."""

    name = "clarabel"
    family = "interior point"
    #: the bilateral law (G x = 0, mu free) through Clarabel's zero cone (conic_rows; tested in tests/plugin_laws);
    #: Tresca friction through epigraph variables (second-order cones in 3D, two linear rows per node in 2D:
    #: dualfem.numerics.epigraph); Coulomb by the fixed point over those Tresca solves (dualfem.numerics.coulomb_run)
    accepts = ("signorini", "bilateral", "tresca", "coulomb")
    description = "Clarabel (interior point, Rust) via its Python interface"
    requires = ("clarabel",)
    #: relative energy-norm error of an unpolished 'Solved' answer (docs/measurements.md)
    tolerance = 1e-5
    #: the second reference solver (an independent method), at dualfem's default tolerances (why not
    #: tighter: docs/measurements.md)
    reference = True
    reference_rank = 10
    reference_params = {"max_iter": 500, "polish": False}   # the reference stays Clarabel's own answer
    defaults = {
        "tol": 1e-10,             # Clarabel's tol_gap_abs = tol_gap_rel = tol_feas
        "tol_ktratio": 1e-8,
        "max_iter": 200,
        "time_limit": 600.0,      # seconds
        "equilibrate_enable": True,
        "direct_solve_method": "qdldl",
        "verbose": False,
        "scale": True,
        "polish": True,           # dualfem's active-set polish (numerics.polish), kept only if it helps
        "coulomb_tol": 1e-10,     # Coulomb: relative change of the threshold that stops the fixed point
        "coulomb_max_iter": 50,   # Coulomb: most Tresca solves
    }

    renamed = {"tol_gap_abs": "tol", "tol_gap_rel": "tol", "tol_feas": "tol"}
    ranges = {"tol_ktratio": "(0, inf)", "equilibrate_enable": bool, "direct_solve_method": None,
              "scale": bool, "polish": bool, "coulomb_tol": "(0, 1)", "coulomb_max_iter": "[1, 1000]"}

    def validate(self) -> None:
        if self.missing() is None:
            _check_direct_method(self.params["direct_solve_method"])
            _check_settings({k: v for k, v in self.params.items() if k not in self.defaults})

    @classmethod
    def backend_options(cls, params: dict) -> dict:
        """Clarabel's own ``DefaultSettings`` fields (``static_regularization_constant``,
        ``iterative_refinement_max_iter``, ...), read from the installed clarabel; set as given."""
        from dualfem.numerics.backend_options import clarabel_options

        return clarabel_options()

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        """Any tier: the interior point to 1e-8, then the polish (measured: docs/measurements.md)."""
        return {"tol": 1e-8, "polish": True}

    def setup(self, qp) -> None:
        import clarabel

        self.qp = qp
        settings = clarabel.DefaultSettings()
        for k, v in self.params.items():
            if k in ("scale", "polish", "tol", "coulomb_tol", "coulomb_max_iter"):
                continue
            setattr(settings, k, v)
        for k in ("tol_gap_abs", "tol_gap_rel", "tol_feas"):
            setattr(settings, k, self.params["tol"])
        self._settings = settings
        if not coulomb_blocks(qp):      # Coulomb: built per Tresca problem of the fixed point (solve)
            self._build(qp)

    def _build(self, qp) -> None:
        """Clarabel's solver for ``qp`` (``self._solver``; ``self._epi`` the epigraph of a frictional QP)."""
        import clarabel

        self._qp_now = qp
        settings = self._settings
        cone = {"nonneg": clarabel.NonnegativeConeT, "zero": clarabel.ZeroConeT, "soc": clarabel.SecondOrderConeT}
        self._epi = None
        if norm_blocks(qp):         # friction: the conic program over [y, t] (dualfem.numerics.epigraph)
            self._epi = e = epigraph(qp, self.params["scale"])
            self._solver = clarabel.DefaultSolver(sp.triu(e.P, format="csc"), e.q, (-e.A).tocsc(),
                                                  np.zeros(e.A.shape[0]), [cone[k](m) for k, m in e.cones], settings)
            return
        self._scaled = s = scale(qp, self.params["scale"])
        self._solver = clarabel.DefaultSolver(sp.triu(s.P, format="csc"), s.q, (-s.A).tocsc(), np.zeros(qp.m_total),
                                              [cone[kind](m) for kind, m in conic_rows(qp.constraints)], settings)

    def solve(self) -> Solution:
        if coulomb_blocks(self.qp):
            return self._coulomb()
        return self._run()

    def _coulomb(self) -> Solution:
        """Coulomb by the fixed point over this solver's Tresca solves (:mod:`dualfem.numerics.coulomb_run`)."""
        def tresca(tq):
            self._build(tq)
            return self._run()

        return coulomb_solution(self, tresca, "clarabel")

    def _run(self) -> Solution:
        """Clarabel on the QP of the last :meth:`_build`, unscaled and polished."""
        qp = self._qp_now
        sol = self._solver.solve()
        name = str(sol.status).split(".")[-1]
        status = _STATUS.get(name, Status.ERROR)
        if self._epi is not None:
            x, z = self._epi.unscale(np.array(sol.x), np.array(sol.z))
        else:
            x, z = self._scaled.unscale(np.array(sol.x), np.array(sol.z))
        info = {}
        if self.params["polish"] and status == Status.SOLVED and not qp.blocks:   # the polish is Signorini's
            x, z, info = polish_if_better(qp, x, z)
        elif self.params["polish"] and status == Status.SOLVED and self._epi is not None:     # friction's
            x, z, info = face_polish_if_better(qp, x, z)
        return Solution(
            solver=self.name, status=status, x=x, multipliers=z,
            iterations={"ipm": int(sol.iterations)}, message=f"clarabel: {name}",
            info={"obj_val": float(sol.obj_val), "solve_time_internal": float(sol.solve_time), **info},
        )


def _check_direct_method(method) -> None:
    """Refuse a ``direct_solve_method`` this Clarabel build lacks (Clarabel says so only at setup)."""
    import clarabel

    def works(m) -> bool:
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        try:
            settings.direct_solve_method = m
            clarabel.DefaultSolver(sp.csc_matrix(np.eye(1)), np.zeros(1), sp.csc_matrix(-np.eye(1)), np.zeros(1),
                                   [clarabel.NonnegativeConeT(1)], settings)
        except Exception:  # Clarabel raises a bare Exception("Bad settings: ...")
            return False
        return True

    if not (isinstance(method, str) and works(method)):
        known = [m for m in ("auto", "qdldl", "faer", "mkl", "cholmod") if works(m)]
        raise InputError(f"parameter 'direct_solve_method' of solver 'clarabel' must be a method this Clarabel "
                         f"build provides (one of {', '.join(known)}), got {method!r}")


def _check_settings(options: dict) -> None:
    """Refuse a backend option value Clarabel's settings object does not take (it says so only at setup)."""
    import clarabel

    for k, v in options.items():
        try:
            setattr(clarabel.DefaultSettings(), k, v)
        except (TypeError, ValueError, AttributeError, OverflowError) as exc:
            raise InputError(f"parameter {k!r} of solver 'clarabel' (a Clarabel setting) was refused by "
                             f"Clarabel: {exc}") from None
