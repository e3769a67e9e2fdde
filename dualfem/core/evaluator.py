"""Independent checks of a solution: recomputed from (x, multipliers) and the QP alone.

Nothing here reads a solver's own residuals. All residuals are scale-free so that one tolerance
works in MPa/mm and in Pa/m alike:

* force scale  f_s = max(|F|_inf, |Kx|_inf, |B'mu|_inf)   (nodal forces)
* length scale l_s = max(|x|_inf, t |F|_inf), t = F'F / F'KF (the displacement the load itself
  sets: non-zero for a solution x = 0 of a loaded problem, never larger than the load's own scale)

==================  =====================================================
``stationarity``    max_i (|r_i| - c eps s_i)_+ / f_s,  r = Kx - F - B'mu: the residual beyond its
                    rounding floor (below); ``stationarity_raw`` = |r|_inf / f_s
``primal``          max(0, -min_j (Bx)_j) / l_s          (max penetration)
``dual``            max(0, -min_j mu_j) / f_s            (negative contact force)
``complementarity`` max_j min(|mu_j (Bx)_j| / (f_s l_s), |mu_j| |b_j|_inf / f_s), b_j row j of B
==================  =====================================================

The table states the Signorini law (``Bx >= 0``, ``mu >= 0``) of today's QPs; with several constraint blocks
(:attr:`dualfem.core.qp.QP.constraints`) ``B`` is the stacked ``qp.G``, mu the concatenated multipliers, and
primal, dual and the complementarity product are each block's law's own (:mod:`dualfem.core.laws`), the
largest over the blocks.

**Complementarity of an inactive row** is the smaller of the scaled product and the force the row carries
(``|mu_j| |b_j|_inf / f_s``: setting mu_j to 0 makes that row exactly complementary and moves the
stationarity residual by that much, in its own scale). A far inactive row (a big-M bound x >= -1e4 with
|x| ~ 10) carrying an interior-point multiplier mu_j ~ tau / 1e4 has a product 1e4 / |x| times larger than
its effect on the answer (an example: docs/measurements.md). The accuracy of x and mu themselves is certified
by the error certificate (:mod:`dualfem.numerics.certify`), which the runner asks of every ``solved``.

**Rounding floor** (Oettli-Prager, componentwise): ``s = |K||x| + |F| + |B'||mu|``; a residual
component within ``c eps s_i`` is what the rounding of evaluating ``K x - F - B'mu`` alone leaves
for the exact answer rounded to double, so it is not counted. ``c`` = :data:`ROUNDING_C` = 4 (dimensionless;
chosen above what exact answers leave and far below what a not converged solve leaves: the measurements
are in docs/measurements.md). The floor excuses only the residual test:
the accuracy of x is judged by the certificate (:mod:`dualfem.numerics.certify`), which catches the
real error of an ill-conditioned (near-incompressible) problem.

**Shifted QPs** (``qp.shift``: the user's unknowns are ``y = x + x_shift``, a QP file with
``h != 0``, Signorini): no scale is taken from the shift, which the input controls. The residuals
are computed twice, in the QP's own unknowns x (data K, F, B) and in the user's unknowns y (data
K, ``F_u = F + K x_shift``, B, ``h_u = B x_shift``, or the user's own ``shift.load`` and ``shift.rhs``
where the QP carries them, as a QP file does: ``K y - F_u - B'mu``, ``B y - h_u``), each frame
with its own scales, and the larger of each pair is reported: a shift that is large against the
solution (a loose bound h = -1e8) cannot make the user's answer look accurate through the size of
x (|x| ~ 1e8), and a shift that is large against x (a forged ``map_x_shift``) cannot make x's
answer look accurate through the size of y. Whatever precision a shift costs (y = x + x_shift
rounded) therefore shows up as a residual.
"""
from __future__ import annotations

import numpy as np

from dualfem.core.constraints import split
from dualfem.core.qp import QP

TINY = 1e-300
EPS = float(np.finfo(float).eps)

#: the names of the four KKT residuals, in report order (defined here only)
RESIDUALS = ("stationarity", "primal", "dual", "complementarity")

#: A defect node is "in contact" when its normal jump is at most this fraction of |x|_inf.
CONTACT_RTOL = 1e-6

#: c of the componentwise rounding floor c eps (|K||x| + |F| + |B'||mu|)_i of the stationarity
#: residual (what exact answers leave: docs/measurements.md)
ROUNDING_C = 4.0


def _shift(qp: QP, x: np.ndarray) -> np.ndarray | None:
    return None if qp.shift is None or qp.shift.x.shape != np.shape(x) else qp.shift.x


def load_length(qp: QP, F: np.ndarray | None = None, KF: np.ndarray | None = None) -> float:
    """t |F|_inf with t = F'F / F'KF: the length the load sets (0 for F = 0), a lower bound of the size
    of K^-1 F in the sense of a Rayleigh quotient; ``F`` defaults to ``qp.F``."""
    F = qp.F if F is None else F
    ff = float(F @ F)
    if ff == 0.0:
        return 0.0
    fkf = float(F @ (qp.K @ F if KF is None else KF))
    return ff / fkf * float(np.abs(F).max()) if fkf > 0 else 0.0


def load_energy(qp: QP, F: np.ndarray | None = None) -> float:
    """|F|_2^2 / sqrt(F'KF) <= sqrt(F'K^-1 F): the energy-norm size the load sets, without a solve."""
    F = qp.F if F is None else F
    ff = float(F @ F)
    if ff == 0.0:
        return 0.0
    fkf = float(F @ (qp.K @ F))
    return ff / np.sqrt(fkf) if fkf > 0 else 0.0


def user_frame(qp: QP, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(y, F_u, h_u) of a shifted QP: the user's unknowns ``y = x + x_shift``, the user's load
    ``F_u = F + K x_shift`` and constraint offsets ``h_u = B x_shift`` (``B y >= h_u``), or the user's own
    data ``shift.load`` and ``shift.rhs`` where the QP carries them (a QP file's ``-q`` and ``h``); None
    for an unshifted QP, and None for a user's problem whose solution is exactly y = 0 (no load, the
    origin feasible: it has no scale of its own; the QP's own unknowns carry it)."""
    shift = _shift(qp, x)
    s = qp.shift
    if shift is None or s is None:
        return None
    Fu = s.load if s.load is not None and s.load.shape == shift.shape else qp.F + qp.K @ shift
    hu = s.rhs if s.rhs is not None and s.rhs.shape == (qp.m_total,) else qp.G @ shift
    if not np.any(Fu) and hu.max(initial=0.0) <= 0.0:
        return None           # no load, origin feasible: the user's solution is y = 0, no relative scale
    return x + shift, Fu, hu


def abs_product(M, v: np.ndarray) -> np.ndarray:
    """|M| v for a sparse M without touching M (a new matrix on |data| and M's index arrays, used for
    one product only: slicing or ``abs`` may sort M's indices in place or copy them)."""
    import scipy.sparse as sp

    M = sp.csr_matrix(M) if M.format not in ("csr", "csc") else M
    cls = sp.csc_matrix if M.format == "csc" else sp.csr_matrix
    return cls((np.abs(M.data), M.indices, M.indptr), shape=M.shape, copy=False) @ v


def _row_max(B) -> np.ndarray:
    """|b_j|_inf of every row of a sparse B (B untouched)."""
    import scipy.sparse as sp

    R = sp.csr_matrix(B)
    out = np.zeros(R.shape[0])
    nz = np.flatnonzero(np.diff(R.indptr))
    if nz.size:
        out[nz] = np.maximum.reduceat(np.abs(R.data), R.indptr[nz])
    return out


def _beyond_floor(qp: QP, x, mu, F, r, fs) -> float:
    """max_i (r_i - c eps (|K||x| + |F| + |B'||mu|)_i)_+ for r = |Kx - F - B'mu|. Only the components with
    r_i > 64 eps f_s are looked at (the others add at most 1.4e-14 f_s); a clean answer costs no product
    with |K|."""
    rows = np.flatnonzero(r > 64.0 * EPS * fs)
    if rows.size == 0:
        return float(r.max(initial=0.0))
    s = (abs_product(qp.K, np.abs(x)) + np.abs(F) + abs_product(qp.G.T, np.abs(mu)))[rows]
    excess = np.maximum(r[rows] - ROUNDING_C * EPS * s, 0.0).max(initial=0.0)
    rest = np.delete(r, rows).max(initial=0.0) if rows.size < r.size else 0.0
    return float(max(excess, rest))


def _frame(qp: QP, x, mu, Kx, F, h) -> dict:
    """The residuals of (x, mu) for ``min 1/2 x'Kx - F'x s.t. G x - h`` in each block's law (module
    docstring): the primal, dual and complementarity terms are the laws' own
    (:mod:`dualfem.core.laws`), the largest over the blocks."""
    G, blocks = qp.G, qp.constraints
    Bmu = G.T @ mu
    fs = max(np.abs(F).max(initial=0.0), np.abs(Kx).max(initial=0.0), np.abs(Bmu).max(initial=0.0), TINY)
    ls = max(float(np.abs(x).max(initial=0.0)), load_length(qp, F), TINY)
    gap = G @ x if h is None else G @ x - h
    r = np.abs(Kx - F - Bmu)
    mus, gaps, scaled = tuple(split(blocks, mu)), split(blocks, gap), split(blocks, mu / fs)
    parts = [b.law.complementarity(ms, gs, b.weights, fs, mus)
             for b, ms, gs in zip(blocks, scaled, split(blocks, gap / ls))]
    comp = parts[0] if len(parts) == 1 else np.concatenate(parts)
    if comp.size and comp.max() > 0:
        if qp.blocks:                    # the distance to each law's complementary multipliers (0 for Signorini)
            nu = np.concatenate([b.law.complementary(mk, gk, b.weights, mus) for b, mk, gk in zip(blocks, mus, gaps)])
            comp = np.minimum(comp, np.abs(mu - nu) * _row_max(G) / fs)
        else:
            comp = np.minimum(comp, np.abs(mu) * _row_max(G) / fs)
    return {
        "stationarity": _beyond_floor(qp, x, mu, F, r, fs) / fs,
        "stationarity_raw": float(r.max(initial=0.0) / fs),
        "primal": float(max(b.law.primal(g) for b, g in zip(blocks, gaps)) / ls),
        "dual": float(max(b.law.dual(mk, b.weights, mus) for b, mk in zip(blocks, mus)) / fs),
        "complementarity": float(comp.max(initial=0.0)),
    }


def residuals(qp: QP, x: np.ndarray, multipliers: np.ndarray) -> dict:
    """KKT residuals of ``(x, multipliers)`` for ``qp`` (see module docstring), plus ``stationarity_raw``,
    the energy ``Pi(x)`` of the QP and ``objective``, the user's objective (for a shifted QP computed
    from the user's unknowns y = x + x_shift: ``1/2 y'Ky - F_u'y``, no cancellation against the shift's
    constant)."""
    x = np.asarray(x, dtype=float)
    mu = np.asarray(multipliers, dtype=float)
    if x.shape != (qp.n,) or mu.shape != (qp.m_total,):
        raise ValueError(f"x must have length {qp.n} and multipliers length {qp.m_total}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(mu))):
        nan = float("nan")
        return {"stationarity": nan, "stationarity_raw": nan, "primal": nan, "dual": nan,
                "complementarity": nan, "energy": nan, "objective": nan, "finite": False}
    Kx = qp.K @ x                        # the one product with K (two for a shifted QP)
    out = _frame(qp, x, mu, Kx, qp.F, None)
    energy = qp.energy(x, Kx)
    if qp.blocks:                        # a law's own objective term (friction's sum g w |gap|; 0 for constraints)
        energy += sum(b.law.energy(g, b.weights) for b, g in zip(qp.constraints, split(qp.constraints, qp.G @ x)))
    objective = energy
    uf = user_frame(qp, x)
    if uf is not None:
        y, Fu, hu = uf
        Ky = qp.K @ y
        user = _frame(qp, y, mu, Ky, Fu, hu)
        out = {k: max(v, user[k]) for k, v in out.items()}
        objective = float(0.5 * y @ Ky - Fu @ y) + (energy - qp.energy(x, Kx) if qp.blocks else 0.0)
    return {**out, "energy": energy, "objective": objective, "finite": True}


def kkt_error(res: dict) -> float:
    """The largest of the four KKT residuals (nan if any is nan)."""
    vals = [res[k] for k in RESIDUALS]
    return float("nan") if any(np.isnan(vals)) else float(max(vals))


def kkt_residuals(res: dict) -> dict:
    """The four KKT residuals of a :func:`residuals` record (without energy and flags)."""
    return {k: res[k] for k in RESIDUALS}


def contact_set(qp: QP, x: np.ndarray, rtol: float = CONTACT_RTOL) -> np.ndarray:
    """Boolean mask of defect nodes in contact: normal jump <= rtol * |x|_inf."""
    gap = qp.B @ x
    return gap <= rtol * max(np.abs(x).max(initial=0.0), TINY)


def friction_summary(qp: QP, x: np.ndarray) -> list[dict]:
    """Per friction block (a law with ``components``): its law, nodes, slipping nodes (slip ``||s_j||`` above
    ``CONTACT_RTOL |x|_inf``, the contact set's tolerance) and the largest slip (length)."""
    out = []
    tol = CONTACT_RTOL * max(float(np.abs(x).max(initial=0.0)), TINY)
    for b in qp.blocks:
        c = getattr(b.law, "components", None)
        if not c:
            continue
        slip = np.linalg.norm((b.G @ x).reshape(-1, c), axis=1)
        out.append({"law": b.law.name, "nodes": int(slip.size), "slipping": int(np.sum(slip > tol)),
                    "max_slip": float(slip.max(initial=0.0))})
    return out


def energy_norm(qp: QP, v: np.ndarray, Kv: np.ndarray | None = None) -> float:
    """sqrt(v' K v) (``Kv``: the product K v, if known)."""
    return float(np.sqrt(max(v @ (qp.K @ v if Kv is None else Kv), 0.0)))


def size_energy(qp: QP, x: np.ndarray, Kx: np.ndarray | None = None) -> float:
    """The energy-norm size of a solution, the denominator of relative errors: max(|x|_K, the load's
    size :func:`load_energy`), so that a solution x = 0 of a loaded problem still has a size. For a
    shifted QP the smaller of that size in the QP's own unknowns and in the user's unknowns
    (``y = x + x_shift``, load ``F_u``): no shift the input controls makes an error look small.
    ``Kx``: the product K x, if known."""
    e = max(energy_norm(qp, x, Kx), load_energy(qp))
    uf = user_frame(qp, x)
    if uf is None:
        return e
    y, Fu, _ = uf
    return min(e, max(energy_norm(qp, y), load_energy(qp, Fu)))


def size_max(qp: QP, x: np.ndarray) -> float:
    """max(|x|_inf, :func:`load_length`), for a shifted QP the smaller of it in the QP's own and in the
    user's unknowns (see :func:`size_energy`)."""
    e = max(float(np.abs(x).max(initial=0.0)), load_length(qp))
    uf = user_frame(qp, x)
    if uf is None:
        return e
    y, Fu, _ = uf
    return min(e, max(float(np.abs(y).max(initial=0.0)), load_length(qp, Fu)))


def force_scale(qp: QP, mu: np.ndarray) -> float:
    """max(|mu|_inf, |F|_inf), for a shifted QP with the smaller of |F| and |F_u| (the multipliers are
    the same in both frames; the load guards the all-open case mu = 0)."""
    f = float(np.abs(qp.F).max(initial=0.0))
    uf = user_frame(qp, np.zeros(qp.n))
    if uf is not None:
        f = min(f, float(np.abs(uf[1]).max(initial=0.0)))
    return max(float(np.abs(mu).max(initial=0.0)), f, TINY)


def compare(qp: QP, x: np.ndarray, mu: np.ndarray, x_ref: np.ndarray, mu_ref: np.ndarray,
            rtol: float = CONTACT_RTOL) -> dict:
    """Relative differences of (x, mu) against a reference (x_ref, mu_ref).

    ``x_energy``: |x - x_ref|_K / |x_ref|_K; ``x_max``: |x - x_ref|_inf / |x_ref|_inf (for a shifted
    QP the sizes of :func:`size_energy` and :func:`size_max`);
    ``multipliers``: |mu - mu_ref|_inf / :func:`force_scale` (max(|mu_ref|_inf, |F|_inf): the load scale
    guards the all-open case where mu_ref = 0); ``energy``: |Pi(x) - Pi(x_ref)| / |Pi(x_ref)|;
    ``contact_mismatch``: number of defect nodes in one contact set and not the other.
    """
    dx = x - x_ref
    ref_e = max(size_energy(qp, x_ref), TINY)
    e_ref = qp.energy(x_ref)
    mu_scale = force_scale(qp, mu_ref)
    c1, c2 = contact_set(qp, x, rtol), contact_set(qp, x_ref, rtol)
    return {
        "x_energy": energy_norm(qp, dx) / ref_e,
        "x_max": float(np.abs(dx).max(initial=0.0) / max(size_max(qp, x_ref), TINY)),
        "multipliers": float(np.abs(mu - mu_ref).max(initial=0.0) / mu_scale),
        "energy": float(abs(qp.energy(x) - e_ref) / max(abs(e_ref), TINY)),
        "contact_mismatch": int(np.count_nonzero(c1 != c2)),
    }


def active_set_solution(qp: QP, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The exact minimizer with ``B_A x = 0`` on the active set A (one sparse KKT solve).

    Returns (x, mu) with mu = 0 off A. If A is the true contact set, this is the exact QP
    solution (check with :func:`certify`): a way to certify a reference without trusting
    any iterative solver.

    Deliberately independent of the solvers' linear algebra: one sparse LU of the full KKT
    matrix, no :class:`dualfem.numerics.linalg.LocalReduction` (which uzawa, pdas, penalty, the active-set
    polish and :mod:`dualfem.numerics.certify` share), so a fault in that shared path cannot certify itself.
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg as sla

    A = np.flatnonzero(active)
    BA = qp.B[A]
    kkt = sp.bmat([[qp.K, BA.T], [BA, None]], format="csc")
    sol = sla.splu(kkt).solve(np.r_[qp.F, np.zeros(A.size)])
    mu = np.zeros(qp.m)
    mu[A] = -sol[qp.n:]
    return sol[:qp.n], mu


def certify(qp: QP, x: np.ndarray, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray, bool]:
    """Exact active-set solution for the contact set of ``x``, and whether it satisfies KKT.

    Returns (x*, mu*, ok): ok is True when the exact solution for that contact set has
    every KKT residual below ``tol``, i.e. the contact set is right and (x*, mu*) is the QP's
    solution up to round-off.
    """
    xs, mus = active_set_solution(qp, contact_set(qp, x))
    return xs, mus, kkt_error(residuals(qp, xs, mus)) <= tol
