"""A rigorous error bound for an answer whose face (active set) holds except on degenerate rows.

At a weakly degenerate solution some rows are closed *and* carry no force (gap_j = 0 and mu_j = 0: e.g. the
corner pairs of a P2 crack under a uniform pressure, whose consistent force is 0 at the triangles' corners; with
friction, a node that sticks with its force on the disc's edge). Strict complementarity fails there, so the
first-order check of :func:`dualfem.numerics.certify.active_set_check` (forces on A above ``margin`` times the
step, gaps off A above it; :func:`dualfem.numerics.faces.blocks_active_set_check` with several laws) cannot
verify the set, and the duality-gap bound of the answer itself is only sqrt(rounding) (its support term
``2 mu'Gx`` is rounding). This module bounds the error through the exact point of the guessed face instead of
claiming that point is the solution.

**The bound** (Signorini notation; every law in :func:`degenerate_bound`). Let A be the guessed set and
(x1, mu1) the exact step's point on it (:func:`dualfem.numerics.certify.refinement_step`):
``K x1 - F - B' mu1 = 0``, ``B_A x1 = 0``, mu1 = 0 off A (friction: the law's held force off the face), and
``|x - x1|_K = |dx|_K`` (computed without forming dx: :func:`dualfem.numerics.linalg.step_size`).

1. x1 is feasible: closed on A, and every row off A has ``gap1_j >= -tol_j`` (its computed gap within the
   rounding ``tol_j`` of that gap: the rounding of the gap itself, ``ROUNDING_C eps (|B||x|)_j``, of the step,
   and of the stationarity residual carried through K^-1; a degenerate row off A is closed at the exact point,
   so its computed gap is rounding of either sign: it is counted closed, as
   :func:`dualfem.numerics.certify.error_bound` counts a penetration within ``FEAS_RTOL``). A row below
   ``-tol_j`` means the set is wrong: no bound (nan).
2. nu = the laws' projection of mu1 (``max(mu1, 0)`` for Signorini) is dual feasible, with the residual
   ``r1 = K x1 - F - B'nu = B'n``, ``n = mu1 - nu`` (the step's forces outside the law's set: rounding on
   degenerate rows), so ``r1'K^-1 r1 = n' D n`` (D = B K^-1 B', dense).
3. The duality-gap bound at (x1, nu) (module docstring of :mod:`dualfem.numerics.certify`):
   ``|x1 - x*|_K <= sqrt(n' D n + 2 support(nu, B x1))``; the support term sums nu_j gap1_j over A, where the
   exact gaps are 0, so the computed term is taken beyond its rounding floor ``support(|nu|, tol)`` (friction
   rows: ``r_j |s1_j| + nu_j . s1_j`` beyond ``(r_j + |nu_j|) tol_j``, as
   :func:`dualfem.numerics.certify._support_floor` removes it).
4. By the triangle inequality, ``|x - x*|_K <= |dx|_K + sqrt(n' D n + 2 max(0, support - floor))``,
   plus ``ROUNDING_C eps |x|_K``: the rounding of |dx|_K itself (x's entries are known to eps, so the computed
   distance of a nearly exact answer is off by about eps |x|_K; measured: without it the bound fell 5e-5 of
   itself below the true error at errors ~1e-12 on a hand-made degenerate QP, tests/test_degenerate_certificate.py).

Every step holds for any A and any answer (a wrong set gives a large n, a penetrating gap1 or a slip against
the held force, never a small bound), so the bound holds against a hostile answer up to the rounding floors
above. It is applied only where the strict check fails and only on the dense path (a Cholesky factor or
eigendecomposition of D_AA, K-solves by a factorization): with CG on D_AA or AMG K-solves the face point's
gaps are known to the solvers' tolerances, not to rounding. No multiplier error is claimed by it: at a
degenerate point the exact forces are not separated from the law's boundary by more than the step's rounding.
"""
from __future__ import annotations

import numpy as np

from dualfem.core import constraints
from dualfem.core.evaluator import EPS, ROUNDING_C, abs_product
from dualfem.core.laws import Friction, Signorini

#: the certificate's note where the set is not verified but the bound through its exact point holds
DEGENERATE_NOTE = ("active set not verified (degenerate rows: closed and without force, or margins below the "
                   "step): x bounded through the face's exact point, multipliers not certified")


def degenerate_bound(qp, x: np.ndarray, A: np.ndarray, mu1: np.ndarray, gap1: np.ndarray, dx_K: float,
                     D: np.ndarray | None, step_rounding: float, size: float, mus: tuple | None = None,
                     ksolve=None) -> float:
    """The energy-norm bound ``(|dx|_K + sqrt(n'D n + 2 max(0, support(nu, G x1) - floor))) / size + ROUNDING_C eps``
    of the module docstring, relative to ``size`` (> 0: the certificate's |x|_K), or nan where x1 violates a law's
    primal constraint beyond rounding (the face A is wrong) or D is not formed.

    Every block of ``qp.constraints`` (stacked rows of ``G``): ``A`` the guessed face (bool per row), ``mu1`` the
    face point's forces (the step's on A, the laws' held values off it: 0 for Signorini, the slip force for
    friction), ``gap1`` its computed ``G x1``, ``dx_K`` = ``|x - x1|_K``, ``D`` the dense ``G K^-1 G'`` (None: not
    formed), ``step_rounding`` the rounding of the step's largest gap change (added to each row's own rounding
    ``ROUNDING_C eps (|G||x|)_j``), ``mus`` the multipliers (split by block) that fix a Coulomb block's threshold
    (the answer's own, as everywhere in the certificate; None: those of ``mu1``). ``nu`` is ``mu1`` projected by
    each law and ``n = mu1 - nu``; a Signorini row off A may penetrate by its rounding only, friction rows have
    no primal constraint, and a QP with another law (a plugin's) gets nan. ``ksolve`` (r -> K^-1 r; None: not
    counted): adds each gap's rounding through the step, ``|G K^-1 (ROUNDING_C eps (|K||x| + |F| + |G'||mu1|))|``
    (the stationarity residual's rounding floor carried to the gaps, as
    :func:`dualfem.numerics.certify.multiplier_floor` carries it to the forces: a face point's gap of size 1e-17
    on a unit displacement is rounding, not a wrong face)."""
    blocks = qp.constraints
    if (D is None and (A.any() or len(blocks) > 1)) or \
            not all(isinstance(b.law, (Signorini, Friction)) for b in blocks):
        return float("nan")
    gap_scale = abs_product(qp.G, np.abs(x))
    tol = step_rounding + ROUNDING_C * EPS * gap_scale
    if ksolve is not None:
        floor_r = abs_product(qp.K, np.abs(x)) + np.abs(qp.F) + abs_product(qp.G.T, np.abs(mu1))
        tol = tol + np.abs(qp.G @ ksolve(ROUNDING_C * EPS * floor_r))
    mus = tuple(constraints.split(blocks, mu1)) if mus is None else mus
    nu, support, floor = np.empty_like(mu1), 0.0, 0.0
    parts = zip(blocks, constraints.split(blocks, np.arange(mu1.size)))
    for b, rows in parts:
        g1, a = gap1[rows], A[rows]
        if isinstance(b.law, Signorini):
            if bool(np.any(g1[~a] < -tol[rows][~a])):
                return float("nan")
        elif b.law.primal(g1) > 0.0:
            return float("nan")
        nu[rows] = b.law.project(mu1[rows], b.weights, mus)
        support += b.law.support(nu[rows], g1, b.weights, mus)
        floor += b.law.support(np.abs(nu[rows]), tol[rows], b.weights, mus)
    n = mu1 - nu
    t1 = float(n @ (D @ n)) if D is not None and n.any() else 0.0
    second = max(t1, 0.0) + 2.0 * max(0.0, support - max(floor, 0.0))
    return float(dx_K + np.sqrt(second)) / size + ROUNDING_C * EPS
