"""Known-answer physics tests (issue 24, item 7): numbers the model or the paper fixes in advance.

* the paper's Tables 1-3 (Zhiltsov & Maksimova 2023): our ``uzawa`` with the paper's settings at
  N = 16 and 32, cell by cell against ``reports/paper_tables.md``, and the paper's own counts where
  they do not depend on the settings the paper leaves unstated (small delta, f3);
* the contraction rate of Uzawa's outer iteration, 1 / (1 + r mu_min), which explains those counts;
* the observed mesh-convergence order against Theorem 1's h^(1/2) (``reports/convergence.md``);
* the two limits of the fracture parameter: delta -> 0 (faces glued: [u_nu] = delta sigma_nu -> 0,
  the uncracked body) and delta -> inf (a free crack with non-penetration), both reached linearly;
* a patch test: a load whose exact solution is linear is reproduced to rounding, with the exact
  contact pressure on the closed defect.

Every test is small (N <= 64) and runs in well under 3 s.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from _defects import patch_check

from dualfem.core import evaluator
from dualfem.experiments import paper
from dualfem.experiments.convergence import errors, triple_rates
from dualfem.post.fields import nodal_displacement, stresses
from dualfem.qp import QP
from dualfem.runner import run
from dualfem.scene import load_scene

E = 69000.0   # the paper's Young's modulus (MPa), the scenes' default


def solve(load: str, solver: str = "pdas", params: dict | None = None, **scene):
    qp = load_scene(load, {"N": 16, **scene}).build()
    sol = run(solver, qp, params or {})
    return qp, sol


# ------------------------------------------------------------------ the paper's Tables 1-3
# Our (k, m) with the paper's settings (r = 1e7, absolute outer test 1e-5 on l, inner 1e-7, Armijo
# step / 2 or / 1.1), plane strain, exactly as reports/paper_tables.md shows them (rows "N=16 strain"
# and "N=32 strain"). Keys: (load, delta, step factor). The table cells, with the paper's values:
#   Table 1 (factor 2): f1, f2, f3 at delta 1e-7, 1e-5, 1e-1   paper f1 18/24 22/33 23/28, f2 22/24 11/16
#                       19/24, f3 1/2 1/2 1/2
#   Table 2 (factor 2) and Table 3 (factor 1.1): f2 at delta 1e-1 ... 1e-9, paper T2 k = 26 21 19 17 15 50 18
#                       111 899, T3 k = 8 12 8 11 10 11 19 121 888
# Why ours differ at moderate delta (the report explains): the paper does not give N (nor the plane
# assumption, nor the quadrature weight, the inner norm, the first Newton iterate, the Armijo constant);
# the outer count there is governed by r mu with mu ~ h, so k grows with N (6-7 at N = 16-32 against the
# paper's 8-26), and m ~ 2k because our energy-norm inner test needs a confirming Newton step. Our
# Tables 2 and 3 coincide: no Newton step is ever shortened by the line search (checked below).
OURS = {
    16: {("f1", 1e-7, 2.0): (19, 38), ("f1", 1e-5, 2.0): (6, 11), ("f1", 1e-1, 2.0): (5, 10),
         ("f2", 1e-7, 2.0): (20, 38), ("f2", 1e-5, 2.0): (6, 11), ("f2", 1e-1, 2.0): (6, 12),
         ("f3", 1e-7, 2.0): (1, 1), ("f3", 1e-5, 2.0): (1, 1), ("f3", 1e-1, 2.0): (1, 1),
         **{("f2", d, f): km for f in (2.0, 1.1) for d, km in zip(
             paper.DELTAS, [(6, 12), (6, 12), (6, 12), (6, 12), (6, 11), (8, 16), (20, 38), (116, 207),
                            (876, 1403)])}},
    32: {("f1", 1e-7, 2.0): (19, 38), ("f1", 1e-5, 2.0): (7, 13), ("f1", 1e-1, 2.0): (6, 12),
         ("f2", 1e-7, 2.0): (21, 40), ("f2", 1e-5, 2.0): (7, 14), ("f2", 1e-1, 2.0): (7, 15),
         ("f3", 1e-7, 2.0): (1, 1), ("f3", 1e-5, 2.0): (1, 1), ("f3", 1e-1, 2.0): (1, 1),
         **{("f2", d, f): km for f in (2.0, 1.1) for d, km in zip(
             paper.DELTAS, [(7, 15), (7, 15), (7, 15), (7, 15), (7, 14), (9, 17), (21, 40), (118, 210),
                            (891, 1428)])}},
}
#: mean |log10(k_ours / k_paper)| over the 27 cells, as the report prints it per setting
DISTANCE = {16: 0.247, 32: 0.209}


@pytest.mark.parametrize("N", sorted(OURS))
def test_paper_tables_iteration_counts(N):
    res = paper.index(paper.tables([N], ["strain"]))
    got = {(load, d, f): (r["k"], r["m"]) for (_, _, load, d, f), r in res.items()}
    assert got == OURS[N], {k: (got.get(k), v) for k, v in OURS[N].items() if got.get(k) != v}
    assert round(paper.distance(res, N, "strain"), 3) == DISTANCE[N]
    assert sum(r["short_steps"] for r in res.values()) == 0          # why Tables 2 and 3 coincide here
    # where the count does not depend on the unstated settings, ours is the paper's:
    # f3 (faces open): one Uzawa iteration (the unconstrained minimizer is admissible, l = 0)
    assert all(res[(N, "strain", "f3", d, 2.0)]["k"] == paper.PAPER_T1[("f3", d)][0] == 1 for d in paper.T1_DELTAS)
    # small delta (r mu ~ 1e7 x delta): within 5 % of the range of the paper's Tables 2 and 3
    for d in (1e-8, 1e-9):
        lo, hi = sorted((paper.PAPER_T2[d][0], paper.PAPER_T3[d][0]))     # 111-121 and 888-899
        for f in (2.0, 1.1):
            k = res[(N, "strain", "f2", d, f)]["k"]
            assert 0.95 * lo <= k <= 1.05 * hi, (d, f, k, (lo, hi))
    # the paper's delta = 1e-9 runs stop on a change of l that is not an error bound: ours say so
    assert res[(N, "strain", "f2", 1e-9, 2.0)]["status"] == "inaccurate"
    # at delta = 1e-8 x is certified, but the absolute test on l leaves the contact forces ~1e-5 off (9.9e-6
    # relative at N = 16, certified against the exact multipliers of the verified set): since issue 26 the
    # multipliers are certified too, so this is not `solved` against the declared 1e-6 either
    assert res[(N, "strain", "f2", 1e-8, 2.0)]["status"] == "inaccurate"


@pytest.mark.parametrize("load, delta", [("f2", 1e-8), ("f2", 1e-9), ("f1", 1e-8)])
def test_uzawa_contraction_rate_is_one_over_one_plus_r_mu(load, delta):
    """Uzawa on the modified Lagrangian is a proximal-point method on the dual: once the contact set is
    fixed, the error of l in the slowest mode contracts by 1 / (1 + r mu) per outer iteration, mu the
    smallest eigenvalue of the dual compliance G_AA W_A (G = B K^-1 B', W = diag(weights), A = the
    contact set). With r = 1e7 and mu ~ delta this is 0.91 at delta = 1e-8 and 0.99 at 1e-9: the
    ~110 and ~900 iterations of the paper's Tables 2-3. Measured from the last half of the changes of l."""
    qp, sol = solve(load, "uzawa", paper.PAPER_OUTER, delta=delta)
    assert sol.info["r"] == pytest.approx(1e7, rel=1e-12)              # the paper's r, in the paper's units
    change = np.array([h["dual_change"] for h in sol.history])
    tail = change[len(change) // 2:]
    observed = (tail[-1] / tail[0]) ** (1.0 / (len(tail) - 1))
    A = evaluator.contact_set(qp, sol.x)
    assert A.sum() == sol.history[-1]["active"] > 0
    G = (qp.B @ sla.splu(sp.csc_matrix(qp.K)).solve(qp.B.T.toarray()))[np.ix_(A, A)]
    mu = np.linalg.eigvals(G @ np.diag(qp.weights[A])).real.min()
    # the interface spring (stiffness w / delta per node) acts beside the elastic body: mu just below delta
    assert 0.9 * delta < mu < delta
    theory = 1.0 / (1.0 + sol.info["r"] * mu)
    assert (1 - observed) / (1 - theory) == pytest.approx(1.0, abs=0.02), (observed, theory)


# ------------------------------------------------------------------ mesh convergence (Theorem 1)
# Triple-wise energy-norm orders on N = 8, 16, 32 against N = 64 (the last triple ends at the reference),
# p = 1/2 log2((e_N^2 - e_2N^2) / (e_2N^2 - e_4N^2)): by Galerkin orthogonality they do not depend on the
# reference's own error, so they agree with the report's N = 16-32-64 orders against N = 1024:
# 0.72 (delta = 0.1), 0.77 (1e-5), 0.84 (1e-9); measured here 0.73/0.72, 0.77/0.76, 0.81/0.84.
# Band: Theorem 1 bounds the H^1 error by C h^(1/2), and with P1 elements and singular points (crack
# tips, clamped corners, the load's jump) the order stays below 1, so 1/2 < p < 1; on these meshes
# the order is pre-asymptotic (the smooth part, O(h), still dominates), within 0.08 of the report's.
REPORT_ORDER = {1e-1: 0.72, 1e-5: 0.77, 1e-9: 0.84}


@pytest.mark.parametrize("delta", sorted(REPORT_ORDER))
def test_convergence_order_against_theorem_1(delta):
    ref = load_scene("f2", {"N": 64, "delta": delta}).build()
    x_ref = run("pdas", ref).x
    errs = []
    for N in (8, 16, 32):
        qp, sol = solve("f2", delta=delta, N=N)
        assert sol.ok
        errs.append(errors(ref, x_ref, qp, sol.x))
    energy = [e["energy_norm"] for e in errs]
    assert energy[0] > energy[1] > energy[2] > 0
    orders = triple_rates(energy)                                      # N = 8-16-32 and 16-32-64
    assert len(orders) == 2 and all(p is not None for p in orders), orders
    for p in orders:
        assert 0.5 < p < 1.0, orders
        assert abs(p - REPORT_ORDER[delta]) <= 0.08, (orders, REPORT_ORDER[delta])
    # L2 error: at least one order higher than h^(1/2) (about O(h) at worst with the tip singularity)
    l2 = [e["L2"] for e in errs]
    assert all(np.log2(a / b) > 1.0 for a, b in zip(l2, l2[1:])), l2


def test_convergence_order_is_higher_when_the_faces_are_glued():
    """The report's finding: as delta -> 0 the faces glue, the crack-tip singularity fades, the order rises."""
    orders = {}
    for delta in (1e-1, 1e-9):
        ref = load_scene("f2", {"N": 64, "delta": delta}).build()
        x_ref = run("pdas", ref).x
        e = []
        for N in (8, 16, 32):
            qp, sol = solve("f2", delta=delta, N=N)
            e.append(errors(ref, x_ref, qp, sol.x)["energy_norm"])
        orders[delta] = triple_rates(e)
    assert all(a + 0.05 < b for a, b in zip(orders[1e-1], orders[1e-9])), orders


# ------------------------------------------------------------------ delta -> 0: the glued limit
def uncracked(qp: QP) -> tuple[QP, sp.csr_matrix]:
    """The body without the defect on the same mesh: every upper copy of a defect node is the lower
    copy (P maps the glued unknowns to the cracked ones), K = P' K_el P, no constraint."""
    nd = qp.geometry.node_dofs
    up, lo = np.asarray(qp.interface.upper), np.asarray(qp.interface.lower)
    target = np.arange(qp.n)
    target[nd[:, up].ravel()] = nd[:, lo].ravel()
    keep = np.unique(target)
    col = np.searchsorted(keep, target)
    P = sp.csr_matrix((np.ones(qp.n), (np.arange(qp.n), col)), shape=(qp.n, keep.size))
    Kg = (P.T @ qp.K_fixed @ P).tocsc()
    return QP(K=Kg, F=P.T @ qp.F, B=sp.csr_matrix((0, keep.size))), P


def test_glued_limit_nu0_is_the_exact_uncracked_state():
    """f3 pulls with 3 MPa; with nu = 0 the body without a defect is in the exact uniform state
    sigma_22 = 3, u = (0, 3 y / E) (the clamp and the free sides impose nothing else). The faces open
    (no contact force: l = 0), so the model's -sigma_nu + [u_nu]/delta = l gives [u_nu] = delta sigma_nu:
    [u_nu] / delta -> 3 at every defect node, and the solution tends to the uncracked one, both with an
    error linear in delta (a factor 10 per decade)."""
    dev, err = [], []
    deltas = (1e-8, 1e-9, 1e-10)
    for delta in deltas:
        qp, sol = solve("f3", delta=delta, nu=0.0)
        assert sol.ok and not evaluator.contact_set(qp, sol.x).any()
        assert np.abs(sol.multipliers).max() <= 1e-12 * np.abs(qp.F).max()   # open faces: l = 0
        jump = qp.B @ sol.x
        assert np.all(jump > 0) and jump.max() <= 3.0 * delta          # opening <= delta sigma_nu
        dev.append(np.abs(jump / delta - 3.0).max() / 3.0)
        X = qp.geometry.nodes
        exact = np.c_[np.zeros(X.shape[1]), 3.0 * X[1] / E]
        err.append(np.abs(nodal_displacement(qp, sol.x) - exact).max() / np.abs(exact).max())
    assert dev[-1] < 1e-4 and err[-1] < 1e-5, (dev, err)
    for seq in (dev, err):
        for a, b in zip(seq, seq[1:]):
            assert 8.0 < a / b < 12.0, seq                             # linear in delta


def test_glued_limit_approaches_the_uncracked_body():
    """nu = 0.3: the uncracked body (same mesh, copies identified, no defect) gives the limit. Its
    discrete normal stress on the defect, sigma_nu = -(K_el u)_upper / w (the traction the upper part
    carries per unit length), is the limit of [u_nu] / delta; displacements and energies converge to it,
    all linearly in delta."""
    qp0, _ = solve("f3", delta=1e-9)
    glued, P = uncracked(qp0)
    xg = P @ sla.spsolve(glued.K, glued.F)
    nd = qp0.geometry.node_dofs
    sigma_nu = -(qp0.K_fixed @ xg)[nd[1, qp0.interface.upper]] / qp0.weights
    assert 2.5 < sigma_nu.min() <= sigma_nu.max() < 3.5                # ~ the 3 MPa pulled on the top side
    e_glued = 0.5 * xg @ (qp0.K_fixed @ xg) - qp0.F @ xg
    dj, dx, de = [], [], []
    for delta in (1e-8, 1e-9, 1e-10):
        qp, sol = solve("f3", delta=delta)
        assert sol.ok and np.all(qp.B @ sol.x > 0)
        dj.append(np.abs((qp.B @ sol.x) / delta - sigma_nu).max() / sigma_nu.max())
        dx.append(np.abs(sol.x - xg).max() / np.abs(xg).max())
        de.append(qp.energy(sol.x) - e_glued)                          # the defect only softens the body
    assert dj[-1] < 1e-3 and dx[-1] < 1e-4, (dj, dx)
    assert all(e < 0 for e in de), de
    for seq in (dj, dx, de):
        for a, b in zip(seq, seq[1:]):
            assert 8.0 < a / b < 12.0, seq


# ------------------------------------------------------------------ delta -> inf: the free crack
def test_free_limit_is_the_crack_with_non_penetration():
    """delta -> inf removes the interface term: the limit is the QP with the elastic stiffness alone and
    the non-penetration constraint (a frictionless crack). f2 closes part of the defect (contact) and
    opens the rest. Displacements, jumps and energies approach the limit as O(1/delta), and
    delta (Pi_delta - Pi_inf) -> 1/2 int |[u_inf]|^2 (the derivative of the energy in 1/delta at the
    limit, the trapezoid rule of the whole jump vector)."""
    base = load_scene("f2", {"N": 16, "delta": 1.0}).build()
    free = QP(K=base.K_fixed, F=base.F, B=base.B, weights=base.weights, maps=base.maps, params=base.params)
    s_inf = run("pdas", free)
    assert s_inf.ok
    closed = evaluator.contact_set(free, s_inf.x)
    assert 0 < closed.sum() < free.m                                   # partial contact: the limit is a crack
    u = nodal_displacement(free, s_inf.x)
    jump = u[free.interface.upper] - u[free.interface.lower]  # whole jump vector (tips: 0)
    half_jump2 = 0.5 * np.sum(free.weights * np.sum(jump**2, axis=1))  # trapezoid rule of 1/2 int |[u]|^2
    dx, dj, de = [], [], []
    for delta in (1e2, 1e3, 1e4):
        qp, sol = solve("f2", delta=delta)
        assert sol.ok and np.array_equal(evaluator.contact_set(qp, sol.x), closed)
        dx.append(np.abs(sol.x - s_inf.x).max() / np.abs(s_inf.x).max())
        dj.append(np.abs(qp.B @ sol.x - free.B @ s_inf.x).max() / np.abs(free.B @ s_inf.x).max())
        de.append(qp.energy(sol.x) - free.energy(s_inf.x))
        assert de[-1] > 0                                              # the interface term stiffens
        assert delta * de[-1] == pytest.approx(half_jump2, rel=10.0 / delta)
    assert dx[-1] < 1e-9, dx
    for seq in (dx, dj, de):
        for a, b in zip(seq, seq[1:]):
            assert 9.0 < a / b < 11.0, seq


# ------------------------------------------------------------------ patch test
@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_patch_uniform_compression_is_exact(plane):
    """f1 presses the top side with 3 MPa. With nu = 0 the exact solution of the body clamped at the
    bottom is linear: u = (0, -3 y / E), sigma_22 = -3, sigma_11 = sigma_12 = 0, and across the defect
    the faces touch ([u] = 0) and carry the pressure l = -sigma_nu + [u_nu]/delta = 3, whatever delta.
    P1 elements contain it, so displacements, element stresses and the pressure mu / w are exact to
    rounding (the 1/delta term conditions the system like delta E / h, hence the tolerance)."""
    cut = load_scene("f1", {"N": 8, "plane": plane})                  # nu = 0.3: lambda != 0 too
    patch_check(cut, cut.build())                                      # K_el: any uniform strain, faces loaded
    for delta in (1e-1, 1e-5, 1e-9):
        qp = load_scene("f1", {"N": 8, "delta": delta, "nu": 0.0, "plane": plane}).build()
        sol = run("pdas", qp)
        assert sol.ok
        X = qp.geometry.nodes
        exact = np.c_[np.zeros(X.shape[1]), -3.0 * X[1] / E]
        u = nodal_displacement(qp, sol.x)
        assert np.abs(u - exact).max() <= 1e-10 * np.abs(exact).max(), delta
        s = stresses(qp, sol.x)
        assert np.abs(s["s22"] + 3.0).max() <= 1e-10 * 3 and np.abs(s["s11"]).max() <= 1e-10 * 3, delta
        assert np.abs(s["s12"]).max() <= 1e-10 * 3, delta
        assert evaluator.contact_set(qp, sol.x).all()
        assert np.abs(qp.pressure(sol.multipliers) - 3.0).max() <= 1e-10 * 3, delta
