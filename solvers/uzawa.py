"""The paper's method: Uzawa on the modified Lagrangian with a generalized Newton-Armijo inner loop.

Zhiltsov & Maksimova (2023), sections 3-4. With l the contact pressure (units of stress, the
paper's alpha_j at defect node j) and w_j the trapezoid weights, the discrete modified Lagrangian is

    M(x, l) = 1/2 x'Kx - F'x + sum_j w_j / (2 r) ( ((l_j - r [x_nu]_j)^+)^2 - l_j^2 ),

(K already holds the 1/delta interface term). Uzawa (outer, counter k):

    x^{k+1} = argmin_x M(x, l^k),      l^{k+1} = (l^k - r [x^{k+1}_nu])^+,

stopping when max_j |l^{k+1}_j - l^k_j| <= tol. The inner minimization is the generalized
Newton method (counter m, summed over all outer iterations): with lambda = l - r B x and the
active set A = {lambda_j > 0},

    gradient  G(x) = K x - F - B' (w * lambda^+),
    Hessian   H(x) = K + r B' diag(w * [j in A]) B,
    x <- x - s d,  d = H^-1 G,

with s = 1 divided by ``step_factor`` until the Armijo test
``M(x - s d) <= M(x) - armijo_c * s * G'd`` holds, and the inner stop
``||x^{m+1} - x^m|| / max(||x^{m+1}||, s_F) < tol_inner`` (s_F the size the load sets:
:func:`dualfem.core.evaluator.load_energy` in the energy norm, ``load_length`` in the Euclidean one; the
test stays relative to the data when x* = 0).

Choices where the paper is silent or misprinted (documented here once):

* The printed gradient beta(t) uses t_{i+} alone where the energy gives the jump t_{i+} - t_{i-};
  we use the jump. The printed Armijo test has no constant and the wrong sign for the descent
  direction -d; we use the standard sufficient decrease with ``armijo_c`` (default 1e-4).
* lambda_j = 0 counts as inactive (the paper lists > 0 and < 0 only).
* The norm of the inner stop test is the paper's V^h norm; we take the energy norm
  ||x||^2 = x'Kx (``inner_norm="energy"``, the natural norm of V^h for this problem and the one
  that is exact and cheap in the reduced space). ``inner_norm="euclidean"`` (the plain
  vector norm) is available with ``linalg="full"``.
* The first Newton iterate is the unconstrained minimizer K^-1 F (the paper does not say; it
  apparently starts from 0, which costs one extra Newton step: its m = 2 for f3). Every later
  inner loop is warm-started from the previous outer iterate.
* Honest stop: the paper's outer test bounds only the last change of l. Two estimates of the
  remaining error of l: change * rho / (1 - rho) with the observed linear rate rho, and the
  proximal-point bound change / (r mu_min) (mu_min = smallest dual compliance, see below), which
  also holds after one outer iteration. With the relative test (``tol_mode="relative"``, the default)
  the iteration goes on until the larger is also <= tol (the answer's multipliers are certified to the
  declared tolerance; why the last change alone is not enough: docs/measurements.md). With the
  paper's absolute test, when the larger exceeds ``error_factor * tol`` the status is ``inaccurate``
  (with both numbers in the message) instead of ``solved``; the iterates and the counts k, m are then
  the paper's.
* Shortcut (``shortcut=True``, with l^0 = 0): if the unconstrained minimizer has no negative
  jump, it already is the answer of the first Uzawa iteration and l^1 = 0; we return it with
  k = 1, m = 1 (one solve).

Choosing r (``r_rule``): Uzawa on the modified Lagrangian is a proximal-point method on the
dual; a dual mode with compliance mu (an eigenvalue of G W, G = B K^-1 B', W = diag(w)) contracts
by 1 / (1 + r mu) per outer iteration. The interface term makes mu ~ delta for small delta, so the
paper's fixed r = 1e7 gives r mu ~ 1e-2 at delta = 1e-9: the ~900 iterations of its Table 2.
``r_rule="auto"`` takes r = r_factor / mu_min, computed from the QP itself (scale-invariant: the
same r mu in MPa/mm and Pa/m), so every mode contracts by 1 / (1 + r_factor); mu_min is the smallest
eigenvalue on G W's range (dependent or duplicated rows of B add zero eigenvalues whose modes change no
x: r = r_factor / 0 gave a singular Newton system). The solver
``uzawa_auto`` is this method with ``r_rule="auto"``; ``uzawa`` keeps the paper's r = 1e7.

The paper's r is a dimensional number (stress / length): 1e7 MPa per unit length for its body of
E = 69000 MPa and width 1. ``r_rule="scaled"`` (the default of ``uzawa``) reads ``r`` in those
units and converts it to the scene's: r_used = r * (E / 69000) / width, with E and width from the
QP's units (``QP.units``). In the paper's units r_used = r exactly (the same iterates as the paper's
method); with E or the length unit scaled by any factor, the iterates scale with them and the
status stays the same. A QP without scene units (a QP file) uses r as given, and says so in
``info["r_units"]``. ``r_rule="fixed"`` uses r as given always (``report paper`` asks for it).

Linear algebra (``linalg``, ``operator``): ``linalg="reduced"`` (default) runs on the contact dual
operator that ``operator`` names (:mod:`dualfem.numerics.dual_operator`; ``auto`` picks by size and
memory, so the method runs at every size and is never skipped for its number of defect unknowns):

* ``operator="dense"``: the exact Schur reduction onto the local unknowns I
  (:class:`dualfem.numerics.linalg.LocalReduction`, K_fixed factorized once, reused across delta,
  loads and solvers); each generalized Hessian is applied by Woodbury on the dense Delassus matrix
  with one |A| x |A| Cholesky factor per active set (cached). Cost: the factorization of K_fixed and
  its Schur complement, then O(|I|^2 m) to form D once (memory 8 (2 |I|^2 + |I| m + m^2) bytes);
  every Newton step is dense work on |I|-sized blocks. mu_min (``r_rule="auto"``) by a dense
  eigensolver on the m x m matrix, O(m^3).
* ``operator="matrix_free"``: all unknowns, sparse. The Newton matrices
  H = K + r B' diag(w * active) B have one sparsity pattern, that of K + B'B (inactive rows stored as
  zeros): :class:`dualfem.numerics.newton_matrix.NewtonMatrix` analyzes it once and factorizes it
  numerically once per new active set (the last ``keep_factors`` kept by active set; counted in
  ``info["factorizations"]``); the start K^-1 F is one solve with the operator's factorization of K
  (shared with the certificate). Cost: one factorization of K, one analysis, one numeric
  factorization of K + B'B per active set met (each about as costly as K's), one sparse solve per
  Newton step; memory: two sparse factors (timings of both paths: docs/measurements.md).
  ``info`` reports the counters (``newton_*``, ``applications``, ``mu_min_applications``).
  mu_min (``r_rule="auto"``, and the honest-stop bound of every run that stops) is estimated by
  Lanczos (ARPACK ``eigsh``, which="SA", relative tolerance ``eig_tol`` = 1e-2) on products
  W^1/2 D W^1/2 v, one K-solve each. An estimate is
  enough: a Ritz value is an upper bound of mu_min, so r = r_factor / mu_min comes out slightly
  smaller than the exact rule's and the slowest dual mode contracts by 1 / (1 + r mu_min), slightly
  slower than 1 / (1 + r_factor) (a 1 % error costs nothing measurable); r only sets the speed of
  the proximal-point iteration, never its fixed point, and the outer stop test (the relative dual
  change, with the error estimates above) guards the accuracy whatever r is. The honest-stop bound
  change / (r mu_min) is then at most that 1 % optimistic.

The two operators compute the same iterates: every iterate after the first is exactly optimal in the
non-local unknowns, so the Newton steps, Armijo tests and stop tests (gradient'step, d'Qd, the
energy norm x'Kx) are the same numbers, computed in the smaller space or the whole one (tested: the
same steps, answers within 1e-10 in the energy norm). ``linalg="full"`` is the textbook path (it
ignores ``operator``): it refactorizes the sparse Hessian at every Newton step, no analysis reused,
and allows ``inner_norm="euclidean"``.

Friction blocks (Tresca, Coulomb; ``accepts``): the frictional modified Lagrangian, the tangential tractions
projected onto their intervals / discs, Coulomb's threshold from the current pressure in the loop
(``coulomb="inner"``) or by the fixed point over Tresca solves (``coulomb="fixed_point"``):
:mod:`dualfem.numerics.friction_uzawa` and :mod:`dualfem.numerics.friction_spaces`.
"""
from __future__ import annotations

import sys
import time

import numpy as np

from dualfem.dual_solver import OPERATORS, DualOperatorSolver
from dualfem.errors import InputError
from dualfem.evaluator import load_energy, load_length
from dualfem.numerics.coulomb import coulomb_fixed_point
from dualfem.numerics.factor import from_param
from dualfem.numerics.friction_spaces import DenseFrictionSpace, Layout, SparseFrictionSpace
from dualfem.numerics.friction_uzawa import FrictionRun, outer
from dualfem.numerics.newton_spaces import FullSpace as _FullSpace
from dualfem.numerics.newton_spaces import ReducedSpace as _ReducedSpace
from dualfem.numerics.newton_spaces import SparseSpace as _SparseSpace
from dualfem.numerics.newton_spaces import armijo_step
from dualfem.qp import UnitsPart
from dualfem.registry import register_solver
from dualfem.solution import Solution, Status

#: the paper's unit system (Zhiltsov & Maksimova 2023, section 5): E in MPa, the unit square
PAPER_E = 69000.0
PAPER_WIDTH = 1.0


def paper_r_in_scene_units(r: float, units: UnitsPart | None) -> tuple[float, str]:
    """(r converted from the paper's units to the scene's, how): r * (E / 69000) / (width / 1).

    r is a stress per length; a scene in other units (``QP.units``: its E and length scale, the
    body's width) gets the same r relative to its own stiffness and size. A QP without units (a
    QP file) uses r as given."""
    if units is None:
        return r, "as given (the QP has no units: E and width)"
    return r * (units.E / PAPER_E) * (PAPER_WIDTH / units.length), f"scaled: r * (E / {PAPER_E:g}) / width"


def _contraction(history: list[dict], last: int = 5) -> float:
    """Observed linear rate of the dual iteration: geometric mean of the last change ratios."""
    ch = [h["dual_change"] for h in history[-(last + 1):]]
    if len(ch) < 3 or min(ch) <= 0:
        return 0.0
    return float(np.exp(np.mean(np.diff(np.log(ch)))))


@register_solver
class Uzawa(DualOperatorSolver):
    """Uzawa on the modified Lagrangian + generalized Newton-Armijo (the paper's method)."""

    name = "uzawa"
    family = "dual"
    accepts = ("signorini", "tresca", "coulomb")
    description = "Uzawa / modified Lagrangian + generalized Newton-Armijo (Zhiltsov & Maksimova 2023)"
    tolerance = 1e-6
    defaults = {
        "r": 1e7,                 # augmentation parameter (stress / length, the paper's units with r_rule="scaled")
        "r_rule": "scaled",       # "scaled": r * (E / 69000 MPa) / width (scene units); "fixed": r as given;
                                  # "auto": r = r_factor / mu_min(B K^-1 B' W)
        "r_factor": 100.0,        # with r_rule="auto": slowest dual mode contracts by 1/(1 + r_factor) per outer it
        "tol": 1e-6,              # on max_j |l^{k+1}_j - l^k_j| / max_j l^{k+1}_j (unit-free; see tol_mode)
        "tol_mode": "relative",   # "absolute": tol in stress units, the paper's test (1e-5 MPa; report paper)
        "tol_inner": 1e-7,        # on ||x^{m+1} - x^m|| / ||x^{m+1}||
        "step_factor": 2.0,       # Armijo backtracking divides s by this (paper: 2 or 1.1)
        "armijo_c": 1e-4,         # sufficient-decrease constant
        "max_iter": 20000,
        "max_inner": 200,         # Newton steps per outer iteration
        "max_backtracks": 80,
        "l0": 0.0,                # starting pressure l^0 (same at every defect node)
        "linalg": "reduced",      # "reduced" (fast, exact: on the dual operator) or "full" (textbook)
        "operator": "auto",       # with linalg="reduced": dense (reduction onto the defect unknowns),
                                  # matrix_free (sparse Newton matrices, one analysis), auto (by size, memory)
        "factor": "auto",         # K factorization: auto (--factor/DUALFEM_FACTOR/fastest) or a backend
        "keep_factors": 4,        # matrix_free: numeric factorizations of Newton matrices kept (by active set)
        "eig_tol": 1e-2,          # matrix_free, r_rule="auto": relative tolerance of the Lanczos estimate of mu_min
        "inner_norm": "energy",   # norm of the inner stop test
        "shortcut": True,         # return the unconstrained minimizer when it is admissible
        "stall_window": 1000,     # stop with 'stagnation' if the dual change has not improved for this many outer its
        "time_limit": 600.0,      # seconds
        "error_factor": 10.0,     # 'inaccurate' if the estimated dual error exceeds this x tol
        "verbose": False,         # print one line per outer iteration to stderr
        "coulomb": "inner",       # Coulomb friction: threshold from the current pressure in the Uzawa loop ("inner",
                                  # the school's way) or the fixed point over Tresca solves ("fixed_point")
        "coulomb_max_iter": 50,   # with coulomb="fixed_point": most Tresca solves
    }
    renamed = {"tol_outer": "tol", "max_outer": "max_iter"}
    ranges = {"r": "(0, inf)", "r_rule": ("scaled", "fixed", "auto"), "r_factor": "(0, inf)",
              "tol_mode": ("relative", "absolute"),
              "tol_inner": "(0, inf)", "step_factor": "(1, inf)", "armijo_c": "(0, 1)", "max_inner": "[1, inf)",
              "max_backtracks": "[1, inf)", "l0": "[0, inf)", "linalg": ("reduced", "full"),
              "operator": OPERATORS, "keep_factors": "[1, inf)", "eig_tol": "(0, 1)",
              "factor": None, "inner_norm": ("energy", "euclidean"), "shortcut": bool, "stall_window": "[1, inf)",
              "error_factor": "(0, inf)", "coulomb": ("inner", "fixed_point"), "coulomb_max_iter": "[1, inf)"}

    def validate(self) -> None:
        super().validate()
        p = self.params
        if p["inner_norm"] == "euclidean" and p["linalg"] != "full":
            raise InputError(f"parameter 'inner_norm' of solver '{self.name}' must be 'energy' with "
                             "linalg='reduced' ('euclidean' needs linalg='full')")

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        return {"tol": tol * 10.0, "tol_inner": tol * 1e-2}

    def skip(self, qp) -> str | None:
        # linalg="reduced": refused only when no operator fits the memory (operator=auto switches
        # to matrix_free above the dense sizes: the paper's method runs at every size)
        return super().skip(qp) if self.params["linalg"] == "reduced" else None

    def setup(self, qp) -> None:
        p = self.params
        self.friction = bool(qp.blocks)
        if self.friction:
            return self._setup_friction(qp)
        self.qp, self.op, self.reduction = qp, None, None
        self._mu, self._mu_info = None, {}
        # the inner test's size has the evaluator's floor (the energy / length the load sets), so that a
        # solution x* = 0 (a crack pushed shut, nothing else loaded) still has a scale: relative to the data
        self._floor2 = (load_energy(qp) if p["inner_norm"] == "energy" else load_length(qp)) ** 2
        if p["linalg"] == "reduced":
            super().setup(qp)            # self.op (dense or matrix_free), self.reduction (dense only)
            if self.op.kind == "dense":
                self.space = _ReducedSpace(qp, p["inner_norm"], reduction=self.op.reduction)
            else:
                self.space = _SparseSpace(qp, self.op, from_param(self), keep=int(p["keep_factors"]))
        else:
            self.space = _FullSpace(qp, p["inner_norm"], from_param(self))
        self.r, self.r_units = paper_r_in_scene_units(float(self.params["r"]), qp.units) \
            if self.params["r_rule"] == "scaled" else (float(self.params["r"]), "as given")
        if self.params["r_rule"] == "auto" and qp.m:
            self.r = float(self.params["r_factor"] / self._mu_min())
            self.r_units = "r_factor / min dual compliance"

    def _mu_min(self) -> float:
        """Smallest eigenvalue of the dual compliance G W (computed once, when first needed): exact
        (dense eigvalsh) on the dense and full paths, a Lanczos estimate on the matrix-free one."""
        if self._mu is None:
            if self.qp.m == 0:
                self._mu = np.inf
            else:
                kw = {"tol": float(self.params["eig_tol"])} if self.space.kind == "matrix_free" else {}
                mu, self._mu_info = self.space.mu_min(self.qp.weights, **kw)
                self._mu = float(max(mu, 1e-300))
        return self._mu

    def solve(self) -> Solution:
        if self.friction:
            return self._solve_friction()
        p, qp, sp_ = self.params, self.qp, self.space
        r, w = self.r, qp.weights
        t_start = time.perf_counter()
        deadline = t_start + p["time_limit"]
        z = sp_.start()
        l = np.full(qp.m, float(p["l0"]))
        k = m_total = 0
        history: list[dict] = []

        def result(status, msg=""):
            x = sp_.full(z)
            info = {**self.op.info()} if self.op is not None else {"operator": "none (linalg='full')"}
            if sp_.kind == "matrix_free":
                info.update(sp_.nm.info())
            info.update({"factorizations": sp_.factorizations, "operator_factorizations": info.get("factorizations", 0),
                         "r": r, "r_units": self.r_units, "linalg": p["linalg"], **self._mu_info})
            return Solution(solver=self.name, status=status, x=x, multipliers=w * l,
                            iterations={"outer": k, "inner": m_total}, history=history, message=msg, info=info)

        self.report_iterate(0, lambda: sp_.full(z), lambda: w * l)     # the start: K^-1 F, l^0
        if p["shortcut"] and p["l0"] == 0.0 and np.all(sp_.B @ z >= 0):
            k, m_total = 1, 1
            self.report_iterate(1, lambda: sp_.full(z), lambda: w * l)
            history.append({"k": 1, "dual_change": 0.0, "inner_steps": 1, "steps": [1.0], "active": 0,
                            "shortcut": True})
            return result(Status.SOLVED, "unconstrained minimizer is admissible (shortcut)")

        best, best_k = np.inf, 0
        while k < p["max_iter"]:
            z, steps, inner_ok, msg = self._inner(z, l, r, w, deadline)
            m_total += len(steps)
            if not np.all(np.isfinite(z)):
                return result(Status.NUMERICAL_ERROR, "NaN/inf in the Newton iterate")
            l_new = np.maximum(0.0, l - r * (sp_.B @ z))
            change = float(np.abs(l_new - l).max(initial=0.0))
            k += 1
            history.append({"k": k, "dual_change": change, "inner_steps": len(steps), "steps": steps,
                            "active": int(np.count_nonzero(l_new > 0)), "inner_converged": inner_ok,
                            "inner_ratios": list(self._ratios)})
            l = l_new
            self.report_iterate(k, lambda z=z: sp_.full(z), lambda l=l: w * l)
            if p["verbose"]:
                print(f"{self.name}: outer {k} dual change {change:.3e} inner {len(steps)} "
                      f"active {history[-1]['active']}", file=sys.stderr)
            if not np.isfinite(change):
                return result(Status.NUMERICAL_ERROR, "NaN/inf in the multiplier update")
            tol = p["tol"] * (1.0 if p["tol_mode"] == "absolute" else max(np.abs(l).max(initial=0.0), 1e-300))
            if change <= tol:
                if not inner_ok:
                    return result(Status.INACCURATE, f"outer test met but last inner loop failed: {msg}")
                rho = _contraction(history)
                est_rate = change * rho / (1.0 - rho) if rho < 1 else np.inf
                # proximal-point bound: the dual is mu_min-strongly concave and its gradient at
                # l^{k+1} is (l^{k+1} - l^k) / r, so |l^{k+1} - l*| <~ change / (r mu_min). It also
                # covers a stop after one or two outer iterations, where no rate can be observed.
                est = max(est_rate, change / (r * self._mu_min()))
                history[-1]["dual_error_estimate"] = est
                if p["tol_mode"] == "relative" and est > tol and k < p["max_iter"]:
                    # the relative test (the default) bounds the estimated error of l, not only its last
                    # change: iterate on (the paper's absolute test stops here, as the paper does)
                    pass
                elif est > p["error_factor"] * tol:
                    return result(Status.INACCURATE,
                                  f"outer test met, but the estimated multiplier error {est:.2g} > "
                                  f"{p['error_factor']:g} x tol (observed rate {rho:.4f}, r x min dual "
                                  f"compliance = {r * self._mu_min():.2g}, which should be >> 1); "
                                  f"use r_rule='auto' (solver uzawa_auto) or a smaller tol")
                else:
                    return result(Status.SOLVED)
            if change < best:
                best, best_k = change, k
            elif k - best_k >= p["stall_window"]:
                return result(Status.STAGNATION, f"dual change has not improved on {best:.3g} for "
                                                 f"{p['stall_window']} outer iterations")
            if time.perf_counter() > deadline:
                return result(Status.TIME_LIMIT, f"time limit {p['time_limit']} s reached")
        return result(Status.MAX_ITER, f"max_iter={p['max_iter']} reached; last dual change {change:.3g}")

    def _inner(self, z, l, r, w, deadline):
        """Generalized Newton-Armijo for min_x M(x, l); returns (z, step sizes, converged, msg)."""
        p, sp_ = self.params, self.space
        B = sp_.B
        steps: list[float] = []
        self._ratios = ratios = []
        for _ in range(int(p["max_inner"])):
            lam = l - r * (B @ z)
            lp = np.maximum(lam, 0.0)
            qg = sp_.qgrad(z)
            G = qg - B.T @ (w * lp)
            coef = np.where(lam > 0, r * w, 0.0)
            d = sp_.newton(coef, G)
            Gd = float(G @ d)
            dQd = sp_.qform(d)
            rBd = r * (B @ d)
            s = 1.0
            if Gd > 0:
                # M(x - s d) - M(x) = -s G'd + s^2/2 d'Qd + sum_j w_j/(2r) D_j, with the remainder of
                # the penalty's linearization D_j = ((lam_j + s r Bd_j)^+)^2 - (lam_j^+)^2 - 2 s r Bd_j lam_j^+
                # evaluated in a cancellation-free form, so a Newton step at round-off level is
                # accepted or refused the same way whatever the linear algebra.
                def rem(t, lam=lam, lp=lp, rBd=rBd):
                    eps = t * rBd
                    lps = lam + eps
                    return np.where((lam > 0) & (lps > 0), eps * eps,
                                    np.maximum(lps, 0.0) ** 2 - lp * lp - 2.0 * eps * lp)

                s = armijo_step(Gd, dQd, rem, w, r, p)
                if s is None:
                    return z, steps, False, "Armijo backtracking failed"
            # Gd <= 0 only happens when G is at round-off level: the full step is taken and the
            # stop test below ends the inner loop.
            z = z - s * d
            steps.append(s)
            nz2 = sp_.norm2(z)
            ratio = s * np.sqrt(max(dQd, 0.0) if p["inner_norm"] == "energy" else float(d @ d)) \
                / np.sqrt(max(nz2, self._floor2, 1e-300))
            ratios.append(float(ratio))
            if ratio < p["tol_inner"]:
                return z, steps, True, ""
            if not np.isfinite(nz2):
                return z, steps, False, "NaN/inf"
            if time.perf_counter() > deadline:
                return z, steps, False, "time limit"
        return z, steps, False, f"max_inner={p['max_inner']} Newton steps without meeting tol_inner"


    # ------------------------------------------------------------------------------------------- friction
    def _setup_friction(self, qp) -> None:
        """Friction blocks (numerics/friction_uzawa.py): the stacked layout, the dense space on the reduction when
        the operator choice is dense, else the sparse one (Newton matrices analyzed once), and r."""
        p = self.params
        self.qp, self.op, self.reduction, self._mu, self._mu_info = qp, None, None, None, {}
        self.lay = Layout(qp)
        self._floor2 = load_energy(qp) ** 2
        if p["linalg"] == "reduced":
            super().setup(qp)
        self.space = SparseFrictionSpace(qp, self.lay, from_param(self))
        if self.op is not None and self.op.kind == "dense":
            try:
                self.space = DenseFrictionSpace(qp, self.lay, reduction=self.op.reduction)
            except ValueError:        # a friction row off the reduction's local unknowns: stay sparse
                pass
        self.r, self.r_units = paper_r_in_scene_units(float(p["r"]), qp.units) \
            if p["r_rule"] == "scaled" else (float(p["r"]), "as given")
        if p["r_rule"] == "auto":
            self.r, self.r_units = float(p["r_factor"] / self._friction_mu_min()), "r_factor / min dual compliance"

    def _friction_mu_min(self) -> float:
        if self._mu is None:
            self._mu = float(max(self.space.mu_min(self.lay.w), 1e-300))
        return self._mu

    def _solve_friction(self) -> Solution:
        p, qp, space, lay = self.params, self.qp, self.space, self.lay
        runs: list[FrictionRun] = []
        info = {"r": self.r, "r_units": self.r_units, "space": space.kind, "coulomb": p["coulomb"]}

        def run(lay_k, z0=None, y0=None) -> FrictionRun:
            report = (lambda k, z, y: self.report_iterate(k, lambda: space.full(z), lambda: lay_k.w * y)) \
                if not runs else None
            out = outer(space, lay_k, p, self.r, self._friction_mu_min, self._floor2, z0=z0, y0=y0, report=report)
            runs.append(out)
            return out

        def result(status, x, mu, msg="", extra=None):
            info.update({"factorizations": space.factorizations, "tresca_solves": len(runs)})
            its = {"outer": sum(r_.k for r_ in runs), "inner": sum(r_.m for r_ in runs), **(extra or {})}
            return Solution(solver=self.name, status=Status(status), x=x, multipliers=mu, iterations=its,
                            history=[h for r_ in runs for h in r_.history], message=msg, info=info)

        if not (lay.coulomb() and p["coulomb"] == "fixed_point"):
            out = run(lay)
            return result(out.status, space.full(out.z), lay.w * out.y, out.message)

        def solve_tresca(qt, warm):
            lay_t = Layout(qt)
            out = run(lay_t, *((None, None) if warm is None else (runs[-1].z, warm[1] / lay_t.w)))
            if out.status != "solved":
                raise _TrescaFailed(out)
            return space.full(out.z), lay_t.w * out.y, {}

        try:
            res = coulomb_fixed_point(qp, solve_tresca, tol=10 * p["tol"], max_iter=int(p["coulomb_max_iter"]))
        except _TrescaFailed as exc:
            out = exc.args[0]
            return result(out.status, space.full(out.z), lay.w * out.y,
                          f"Tresca solve {len(runs)} of the Coulomb fixed point: {out.status} {out.message}")
        msg = "" if res.status == "solved" else \
            f"Coulomb fixed point {'stalled' if res.stalled else 'hit coulomb_max_iter'} (change {res.changes[-1]:.3g})"
        info.update(res.details())
        return result(res.status, res.x, res.mu, msg, res.summary())


class _TrescaFailed(Exception):
    """A Tresca solve inside the Coulomb fixed point ended without ``solved`` (its FrictionRun in args[0])."""


@register_solver
class UzawaAuto(Uzawa):
    """The same method with r chosen from the problem's dual compliance (see module docstring)."""

    name = "uzawa_auto"
    description = "Uzawa / modified Lagrangian + Newton-Armijo, r = 100 / (min dual compliance), relative tolerance"
    tolerance = 1e-8
    defaults = {**Uzawa.defaults, "r_rule": "auto", "tol_mode": "relative", "tol": 1e-9}

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        # the relative dual change cannot go much below ~1e-10: with r ~ 100/delta, r times the
        # round-off of the jump is ~1e-10 of the pressure at delta = 1e-9 (the floor 1e-9: docs/measurements.md)
        return {"tol": max(tol * 1e-2, 1e-9), "tol_inner": max(tol * 1e-2, 1e-12)}
