"""MPRGP: Dostal's modified proportioning with reduced gradient projections, on the contact dual.

With the Delassus matrix ``D = B K^-1 B'`` (symmetric positive definite, m x m) and the gaps at
zero contact force ``b0 = B K^-1 F`` (the gaps at forces mu are ``D mu + b0``), the contact forces
minimise

    q(mu) = 1/2 mu'D mu + b0'mu   over  mu >= 0,         gradient g(mu) = D mu + b0 = the gaps,

and ``x = K^-1 (F + B'mu)`` (one K-solve). MPRGP (Dostal & Schoeberl 2005; Dostal, *Optimal
quadratic programming algorithms*, 2009) splits the gradient into the free gradient
``phi`` (components with mu_j > 0) and the chopped gradient ``beta`` (``min(g_j, 0)`` where
mu_j = 0); the projected gradient is ``g^P = phi + beta``. Each iteration is one of

* a **CG step** along the conjugate direction p when it stays feasible (one product D p);
* an **expansion step**: the largest feasible CG step, then a projected gradient step of fixed
  length alpha in (0, 2/|D|] along the free gradient (adds constraints to the active set; two
  products: D p and the gradient recomputed at the projected point);
* a **proportioning step**: a minimisation along beta when ``|beta|^2 > Gamma^2 phi~'phi``
  (frees constraints; ``phi~`` is the free gradient reduced so that a step alpha stays feasible;
  one product).

Stopping test (scale-free, in the original variables whatever the preconditioner):
``|g^P(mu)| <= tol |b0|``. |D| (of the scaled operator when scaled) is estimated by
``power_iter`` power iterations in the setup (``alpha = alpha_factor / |D|_est``). ``b0 = 0`` (no
load) gives mu = 0 at once.

**Operator** (``operator``, :class:`dualfem.numerics.dual_operator.DualOperator`): ``dense`` is the
exact reduction onto the defect unknowns, D a dense m x m matrix (a product costs 2 m^2 flops);
``matrix_free`` never forms D: one sparse factorization of K, and each product ``D v = B K^-1 B'v``
is one forward/backward solve with it; ``auto`` (default) picks by size and memory. So in the
matrix-free case **an iteration costs one K-solve** (an expansion two) on top of the one
factorization of K, plus fixed costs: ``power_iter`` solves for |D| in the setup, one block solve
of 16 right-hand sides for the diagonal estimate (used by the polish's Jacobi-PCG and by
precond=jacobi), the polish's CG iterations (a few: it starts from the MPRGP forces), one solve
each for ``b0`` and x. ``info`` reports every count (``applications``: products D v, a block of k
counting k; ``solves``; ``cg_iterations`` of the polish; ``factorizations``) next to MPRGP's own
(``iterations``: cg / expansion / proportioning).

**Preconditioner** (``precond``, :mod:`dualfem.numerics.dual_precond`; none costs a K-solve;
``info["precond"]`` says which one ran). ``auto`` (default): ``dirichlet`` with the matrix-free
operator, where a product is a K-solve, ``none`` with the dense one, where a product is so cheap
that the preconditioner's setup would cost more than it saves (docs/measurements.md).

* ``dirichlet``: Dostal's preconditioning in face with FETI's Dirichlet preconditioner
  ``M^-1 = W B S_loc B' W`` (``W = diag(B B')^-1``; S_loc the Schur complements of K onto each
  crack's unknowns from ``layers`` rings of elements around it, clamped outside: one small dense
  block per crack, built once in the setup). The CG directions are built from
  ``z_F = (M^-1)_FF phi_F`` on the free set F only (expansion and proportioning steps unchanged),
  so a CG step still costs one product. cond(D) grows as crack length / h (the modes smooth along
  a crack); M^-1 removes the modes shorter than about ``layers`` elements (CG steps with and without
  it: benchmarks/results/mprgp_precond/mprgp_precond.md, docs/measurements.md);
* ``lumped``: the same with FETI's lumped ``M^-1 = W B K B' W`` (spectrally a constant here: it
  does not cut iterations, kept for comparison);
* ``jacobi``: the change of variables ``mu = S nu``, ``S = diag(D)^-1/2`` (the operator's
  diagonal: exact when dense, a calibrated estimate when matrix-free): MPRGP on ``S D S`` and
  ``S b0`` with the bounds ``nu >= 0``, exactly the bounds mu >= 0 (diag(D) is nearly constant on
  these scenes: no gain, kept for comparison);
* ``none``: plain MPRGP (with the dense operator, the numbers of the former implementation exactly).

Then, as pdas does, the result is polished on its final active set A = {mu > 0}: the exact
minimiser of q on that face (``D_AA mu_A = -b0_A``: a dense Cholesky solve, or, matrix-free,
Jacobi-PCG on D_AA warm-started from the MPRGP forces, one K-solve per CG iteration, counted in
``cg_iterations``) is kept if it is consistent (mu_A >= 0, inactive gaps >= 0), and (dense
operator) ``refine`` iterative-refinement steps of the full KKT system
(:func:`dualfem.numerics.polish.refine_on_active_set`) remove the rounding error of the reduction.
Multipliers are nodal contact forces (mu >= 0, ``Kx - F = B'mu``).

**Friction** (Tresca / Coulomb blocks): MPGP, Dostál's generalization to separable convex sets (half-lines and
the friction discs, :mod:`dualfem.numerics.friction_mpgp`), on the dual operator of all blocks stacked
(:func:`dualfem.numerics.friction_dual.stacked_qp`), without a preconditioner, then (``friction_polish``) HSW's
semismooth Newton from its answer (:mod:`dualfem.numerics.friction_newton`: the exact point of its sets, kept if it
converges). Coulomb: the fixed point g <- mu_f lambda / w over such Tresca solves, warm-started
(:mod:`dualfem.numerics.coulomb`; ``coulomb_tol``, ``coulomb_max_iter``; stalled or not converged: ``max_iter``).
"""
from __future__ import annotations

import time

import numpy as np

from dualfem.dual_solver import OPERATORS, DualOperatorSolver
from dualfem.numerics import dual_precond as dp
from dualfem.numerics.coulomb import coulomb_fixed_point
from dualfem.numerics.dual_operator import power_norm
from dualfem.numerics.factor import from_param
from dualfem.numerics.friction_dual import FrictionLayout, friction_operator, layout_refusal
from dualfem.numerics.friction_mpgp import mpgp
from dualfem.numerics.friction_newton import semismooth_newton
from dualfem.numerics.polish import refine_on_active_set
from dualfem.registry import register_solver
from dualfem.solution import Solution, Status


def mprgp(matvec, b0: np.ndarray, alpha: float, gamma: float, tol: float, max_iter: int,
          time_limit: float, verbose: bool = False, precond=None, unscale: np.ndarray | None = None,
          report=None):
    """MPRGP for min 1/2 mu'D mu + b0'mu, mu >= 0. Returns (mu, counts, status, message, history).

    ``report(k, mu)``: called with the iterate after each iteration k (k = 0: the start), if given.

    ``precond(r, free)``: the preconditioner in face (z on the free set, 0 elsewhere), None for
    plain MPRGP. ``unscale``: for a scaled problem (``mu = S nu``: D = S D0 S, b0 = S b0_orig), the
    vector 1/s, so that the stopping test ``|g^P| <= tol |b0|`` is taken in the original variables.
    """
    mu = np.zeros(b0.size)
    g = b0.copy()                                   # D mu + b0 at mu = 0
    counts = {"cg": 0, "expansion": 0, "proportioning": 0}
    history: list[dict] = []
    u = np.ones(b0.size) if unscale is None else unscale
    nb0 = np.linalg.norm(b0 if unscale is None else b0 * u)
    target = tol * nb0
    t0 = time.perf_counter()

    def pnorm(phi_, beta_):
        return np.linalg.norm(phi_ + beta_ if unscale is None else (phi_ + beta_) * u)

    def prec(phi_, free_):
        return phi_.copy() if precond is None else precond(phi_, free_)

    free, phi, beta = _split(mu, g)
    p = prec(phi, free)
    k = 0
    report = report or (lambda k_, mu_: None)
    report(0, mu)
    while True:
        gp = pnorm(phi, beta)
        done = _stop(gp, target, nb0, k, max_iter, t0, time_limit)
        if done is not None:
            return mu, counts, done[0], done[1], history
        k += 1
        phit = np.where(free, np.minimum(mu / alpha, phi), 0.0)
        if beta @ beta <= gamma ** 2 * (phit @ phi):
            mu, g, free, phi, beta, p, kind = _face_step(matvec, b0, alpha, prec, mu, g, p, free, phi)
        else:
            mu, g, free, phi, beta, p = _proportioning_step(matvec, prec, mu, g, beta)
            kind = "proportioning"
        counts[kind] += 1
        report(k, mu)
        if verbose:
            history.append({"iter": k, "kind": kind, "active": int((~free).sum()),
                            "proj_grad": float(pnorm(phi, beta))})


def _split(mu, g):
    """(free set ``mu > 0``, free gradient phi, chopped gradient beta) of the gradient g = D mu + b0."""
    free = mu > 0
    phi = np.where(free, g, 0.0)
    beta = np.where(free, 0.0, np.minimum(g, 0.0))
    return free, phi, beta


def _stop(gp, target, nb0, k, max_iter, t0, time_limit):
    """(status, message) when MPRGP stops before iteration k + 1 (projected gradient ``gp`` at most
    ``target``, ``max_iter`` iterations done, ``time_limit`` seconds since ``t0`` spent), else None."""
    if gp <= target:
        rel = gp / max(nb0, 1e-300)
        return Status.SOLVED, f"converged: |g^P| = {rel:.1e} |b0|"
    if k >= max_iter:
        return Status.MAX_ITER, f"no convergence in {max_iter} iterations (|g^P|/|b0| = {gp / nb0:.1e})"
    if time.perf_counter() - t0 > time_limit:
        return Status.TIME_LIMIT, f"time limit {time_limit:g} s after {k} iterations"
    return None


def _face_step(matvec, b0, alpha, prec, mu, g, p, free, phi):
    """One step in the face: the (preconditioned) CG step along p where it stays feasible, else the
    feasible step to the boundary, then an expansion step (projected gradient with step ``alpha``)
    and a restart. Returns (mu, g, free, phi, beta, p, kind) with kind "cg" or "expansion"."""
    if not p.any():
        p = prec(phi, free)
    Ap = matvec(p)
    pAp = p @ Ap
    a_cg = (g @ p) / pAp
    pos = p > 0
    a_f = np.min(mu[pos] / p[pos]) if pos.any() else np.inf
    if a_cg <= a_f:
        mu = mu - a_cg * p
        g = g - a_cg * Ap
        free, phi, beta = _split(mu, g)
        z = prec(phi, free)
        p = z - ((z @ Ap) / pAp) * p
        return mu, g, free, phi, beta, p, "cg"
    mu = np.maximum(mu - a_f * p, 0.0)
    g = g - a_f * Ap
    free, phi, _ = _split(mu, g)
    mu = np.maximum(mu - alpha * phi, 0.0)
    g = matvec(mu) + b0
    free, phi, beta = _split(mu, g)
    p = prec(phi, free)
    return mu, g, free, phi, beta, p, "expansion"


def _proportioning_step(matvec, prec, mu, g, beta):
    """The proportioning step: exact line search along the chopped gradient ``beta`` (releases
    constraints), projected. Returns (mu, g, free, phi, beta, p)."""
    Ad = matvec(beta)
    a = (g @ beta) / (beta @ Ad)
    mu = np.maximum(mu - a * beta, 0.0)
    g = g - a * Ad
    free, phi, beta = _split(mu, g)
    p = prec(phi, free)
    return mu, g, free, phi, beta, p


@register_solver
class MPRGPSolver(DualOperatorSolver):
    """MPRGP on the contact dual (dense or matrix-free operator, preconditioned), with a final face polish."""

    name = "mprgp"
    family = "dual"
    #: friction: MPGP over half-lines and discs (dualfem.numerics.friction_mpgp); Coulomb by the fixed point
    #: over Tresca solves (dualfem.numerics.coulomb)
    accepts = ("signorini", "tresca", "coulomb")
    description = "MPRGP (Dostal's modified proportioning / reduced gradient projections) on the dual (exact)"
    tolerance = 1e-9
    exact = True
    defaults = {
        "tol": 1e-12,             # stop at |g^P(mu)| <= tol |b0| (projected gradient of the dual)
        "max_iter": 10000,
        "time_limit": 600.0,      # seconds of solve time
        "verbose": False,         # keep a per-iteration history
        "operator": "auto",       # dual operator: dense reduction, matrix_free (K-solves), auto (by size, memory)
        "factor": "auto",         # K factorization: auto (--factor/DUALFEM_FACTOR/fastest) or a backend
        "precond": "auto",        # auto (matrix_free: dirichlet in 2D, lumped in 3D; else none) | none | jacobi |
                                  # lumped | dirichlet
        "layers": 4,              # precond=dirichlet: rings of elements of the local Schur complements
        "gamma": 1.0,             # proportioning parameter Gamma > 0
        "alpha_factor": 1.8,      # expansion steplength alpha = alpha_factor / |D|_est, in (0, 2]
        "power_iter": 20,         # power iterations for |D|
        "refine": 1,              # iterative-refinement steps of the final KKT system (dense operator)
        "coulomb_tol": 1e-11,     # friction, Coulomb: relative change of the threshold that stops the fixed point
        "coulomb_max_iter": 50,   # ... and its most Tresca solves
        "friction_polish": True,  # friction: HSW's Newton from MPGP's answer (its sets), kept if it converges
    }

    # "matrixfree" (the old spelling) passes the range check; validate() normalises it to matrix_free
    ranges = {"operator": OPERATORS + ("matrixfree",), "factor": None, "precond": ("auto", *dp.PRECONDS),
              "layers": "[0, inf)", "gamma": "(0, inf)", "alpha_factor": "(0, 2]", "power_iter": "[1, inf)",
              "refine": "[0, inf)", "coulomb_tol": "(0, 1)", "coulomb_max_iter": "[1, inf)",
              "friction_polish": bool}

    @classmethod
    def tolerance_params(cls, tol: float) -> dict:
        return {"tol": min(float(tol) * 1e-3, cls.defaults["tol"])}

    def skip(self, qp) -> str | None:
        refusal = layout_refusal(qp) if qp.blocks else None
        return refusal if refusal is not None else super().skip(qp)

    def setup(self, qp) -> None:
        if qp.blocks:                  # friction: the dual operator of all blocks stacked, no preconditioner
            self.qp, self.precond_kind, self.scale, self.precond = qp, "none", None, None
            self.op = friction_operator(qp, self.params["operator"], from_param(self), self.tolerance)
            self.reduction = None
            self.norm = self.op.norm_estimate(int(self.params["power_iter"])) if self.op.b0.size else 0.0
            return
        super().setup(qp)
        op, kind = self.op, self.params["precond"]
        if kind == "auto":     # matrix-free: FETI's Dirichlet in 2D, the lumped one in 3D
            kind = ("dirichlet" if dp.dirichlet_by_default(qp) else "lumped") if op.kind == "matrix_free" else "none"
        self.precond_kind = kind
        self.scale = self.precond = None
        self.norm = 0.0
        if not qp.m:
            return
        if kind == "jacobi":
            self.scale = dp.jacobi_scaling(op)
        elif kind == "lumped":
            self.precond = dp.FacePreconditioner(dp.lumped_inverse(qp))
        elif kind == "dirichlet":
            self.precond = dp.FacePreconditioner(dp.dirichlet_inverse(qp, int(self.params["layers"])))
        iters = int(self.params["power_iter"])
        self.norm = op.norm_estimate(iters) if self.scale is None else power_norm(self._matvec, qp.m, iters)

    def _matvec(self, v: np.ndarray) -> np.ndarray:
        """The (scaled) operator MPRGP iterates with: D v, or S D S v."""
        if self.scale is None:
            return self.op.apply(v)
        s = self.scale
        return s * self.op.apply(s * v)

    def _tresca(self, layout: FrictionLayout, mu0, counts: dict, deadline: float):
        """MPGP for the Tresca radii of ``layout``, then HSW's Newton from its answer (exact sets: the polish);
        returns (mu, converged, message) and adds the counts."""
        p, op = self.params, self.op
        r = layout.radius(np.zeros(op.b0.size))
        res = mpgp(op.apply, op.b0, layout, r, p["alpha_factor"] / self.norm, p["gamma"], p["tol"],
                   int(p["max_iter"]), deadline, mu0)
        for key, v in res.counts.items():
            counts[key] = counts.get(key, 0) + v
        mu = res.mu
        if res.converged and p["friction_polish"]:
            c = 1.0 / op.diagonal().mean()
            pol = semismooth_newton(op, layout, c, 1e-13 if op.kind == "dense" else 1e-11, 10, mu0=mu)
            counts["polish_newton"] = counts.get("polish_newton", 0) + pol.steps
            if pol.converged:
                mu = pol.mu
        return mu, res.converged, res.message

    def _solve_friction(self) -> Solution:
        """Tresca: MPGP (+ a Newton polish); Coulomb: the fixed point over Tresca solves, each by MPGP."""
        p, op, qp = self.params, self.op, self.qp
        deadline = time.perf_counter() + p["time_limit"]
        counts: dict = {"cg": 0, "expansion": 0, "proportioning": 0}
        layout = FrictionLayout.of(qp)
        if not layout.coulomb.any():
            mu, ok, message = self._tresca(layout, None, counts, deadline)
            status = Status.SOLVED if ok else (Status.TIME_LIMIT if time.perf_counter() > deadline else Status.MAX_ITER)
            return Solution(solver=self.name, status=status, x=op.x_of(mu), multipliers=mu, iterations=counts,
                            message=message, info={"alpha": p["alpha_factor"] / self.norm, "precond": "none",
                                                   "friction": "mpgp", **op.info()})
        failed: list[str] = []

        def solve_tresca(qpt, warm):
            mu, ok, msg = self._tresca(FrictionLayout.of(qpt), None if warm is None else warm[1], counts, deadline)
            if not ok:
                failed.append(msg)
            return op.x_of(mu), mu, {}

        fp = coulomb_fixed_point(qp, solve_tresca, float(p["coulomb_tol"]), int(p["coulomb_max_iter"]))
        status = Status.SOLVED if fp.status == "solved" and not failed else Status.MAX_ITER
        message = (f"Coulomb fixed point {fp.status} in {fp.iterations} Tresca solves by MPGP"
                   + (f"; an inner solve failed: {failed[-1]}" if failed else ""))
        return Solution(solver=self.name, status=status, x=fp.x, multipliers=fp.mu,
                        iterations={**counts, **fp.summary()}, message=message,
                        info={"alpha": p["alpha_factor"] / self.norm, "precond": "none", "friction": "mpgp",
                              "coulomb_changes": fp.changes, **op.info()})

    def solve(self) -> Solution:
        if self.qp.blocks:
            return self._solve_friction()
        p, op, qp = self.params, self.op, self.qp
        b0 = op.b0
        if qp.m == 0 or not np.any(b0):
            mu = np.zeros(qp.m)
            return Solution(solver=self.name, status=Status.SOLVED, x=op.x_of(mu), multipliers=mu,
                            iterations={"cg": 0, "expansion": 0, "proportioning": 0},
                            message="no load on the constraints (b0 = 0): mu = 0",
                            info={"precond": self.precond_kind, **op.info()})
        alpha = p["alpha_factor"] / self.norm
        s = self.scale

        def report(k: int, nu: np.ndarray) -> None:     # the iterate in the QP's forces (unscaled), x lazily
            self.report_iterate(k, lambda: op.x_of(nu if s is None else s * nu), lambda: nu if s is None else s * nu)

        mu, counts, status, message, history = mprgp(
            self._matvec, b0 if s is None else s * b0, alpha, p["gamma"], p["tol"], int(p["max_iter"]),
            p["time_limit"], p["verbose"], precond=self.precond, unscale=None if s is None else 1.0 / s,
            report=report if self._iterate_monitor is not None else None)
        if s is not None:
            mu = s * mu
        info: dict = {"alpha": alpha, "norm_D_est": self.norm, "precond": self.precond_kind}
        if status == Status.SOLVED:
            mu, info["face_polish"] = self._face_polish(mu, b0)
        x = op.x_of(mu)
        if status == Status.SOLVED and op.reduction is not None and p["refine"] > 0:
            x, mu, info["refinement_steps"] = self._refine(x, mu, int(p["refine"]))
        info["n_active"] = int((mu > 0).sum())
        info.update(op.info())
        return Solution(solver=self.name, status=status, x=x, multipliers=mu, iterations=counts,
                        history=history, message=message, info=info)

    def _face_polish(self, mu: np.ndarray, b0: np.ndarray) -> tuple[np.ndarray, bool]:
        """Exact minimiser of q on the face {mu_j = 0 off A}, kept if consistent
        (:meth:`dualfem.numerics.dual_operator.DualOperator.face_minimiser`)."""
        try:
            mu_p = self.op.face_minimiser(mu, self.params["tol"])
        except (np.linalg.LinAlgError, ValueError):
            return mu, False
        return (mu, False) if mu_p is None else (mu_p, True)

    def _refine(self, x, mu, steps):
        """Iterative refinement on the final active set (:func:`dualfem.numerics.polish.refine_on_active_set`)."""

        return refine_on_active_set(self.qp, self.op.reduction, x, mu, steps)
