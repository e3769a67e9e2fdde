"""The matrix-free paths of uzawa, uzawa_auto and penalty: sparse Newton matrices on one pattern.

``operator="matrix_free"`` must give the dense path's answers (the same iterates for uzawa), the
paper's method must never be skipped for its number of defect unknowns, and the Newton matrices'
pattern must be analyzed once (:mod:`dualfem.numerics.newton_matrix`).
"""
from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse as sp
from _backend import newton_analyses

from dualfem.core.registry import solvers
from dualfem.core.scene import load_scene
from dualfem.core.solution import Status
from dualfem.numerics.newton_matrix import NewtonMatrix


@functools.cache
def cracks(delta: float, n: int = 3, h: float = 0.04):
    """A small scene with n x n short cracks (gmsh, load f1): a few hundred unknowns, m ~ 100."""
    rng = np.random.default_rng(1)
    defects = []
    for i in range(n):
        for j in range(n):
            cx, cy = (j + 0.5) / n, 0.05 + 0.9 * (i + 0.5) / n
            a = rng.uniform(0, np.pi)
            dx, dy = 0.25 / n * np.cos(a), 0.25 / n * np.sin(a)
            defects.append({"points": [[cx - dx, cy - dy], [cx + dx, cy + dy]], "curve": "polyline"})
    return load_scene("f1", {"mesh": "gmsh", "mesh_size": h, "tip_size": h, "defects": defects,
                             "delta": delta}).build()


def _solve(name: str, qp, **params):
    s = solvers()[name](**params)
    s.setup(qp)
    return s.solve()


def _energy(qp, x) -> float:
    return float(np.sqrt(max(float(x @ (qp.K @ x)), 0.0)))


def _agree(qp, a, b, tol: float, tol_mu: float | None = None) -> None:
    """x within tol in the energy norm, multipliers within tol_mu (default tol) relative to max |mu|."""
    dx = _energy(qp, a.x - b.x) / _energy(qp, a.x)
    dmu = np.abs(a.multipliers - b.multipliers).max() / max(np.abs(a.multipliers).max(), 1e-300)
    assert dx <= tol and dmu <= (tol if tol_mu is None else tol_mu), (dx, dmu)


@pytest.mark.parametrize("delta", [1e-5, 1e-9])
def test_uzawa_matrix_free_has_the_dense_iterates(delta):
    """The paper's r: the same outer/inner counts and Armijo steps, answers within 1e-10 (at delta
    = 1e-9 the paper's r needs ~1000 outer iterations: the first 40 are compared)."""
    qp = cracks(delta)
    cap = {"max_iter": 40} if delta < 1e-6 else {}
    dense = _solve("uzawa", qp, operator="dense", **cap)
    free = _solve("uzawa", qp, operator="matrix_free", **cap)
    assert dense.info["operator"] == "dense" and free.info["operator"] == "matrix_free"
    assert dense.status == free.status and dense.iterations == free.iterations
    assert [h["steps"] for h in dense.history] == [h["steps"] for h in free.history]
    _agree(qp, dense, free, 1e-10)
    assert free.info["newton_analyses"] == newton_analyses(free.info) and free.info["factorizations"] >= 1


@pytest.mark.parametrize("delta", [1e-5, 1e-9])
def test_uzawa_auto_matrix_free_agrees(delta):
    """r = r_factor / mu_min: with a tight Lanczos tolerance the same r and iterates as the dense
    eigensolver; with the default rough one (1e-2) r is a little smaller (a Ritz value bounds mu_min
    from above) and the answer is the same to the solver's accuracy. At delta = 1e-9 the multipliers
    are determined only to ~2.5e-10 by rounding (r ~ 100 / delta times the rounding of the jump: the
    dense and the textbook full path differ by as much), so they are compared to 1e-9 there."""
    qp = cracks(delta)
    tol_mu = 1e-10 if delta > 1e-6 else 1e-9
    dense = _solve("uzawa_auto", qp, operator="dense")
    tight = _solve("uzawa_auto", qp, operator="matrix_free", eig_tol=1e-12)
    assert dense.status == tight.status == Status.SOLVED
    assert tight.info["r"] == pytest.approx(dense.info["r"], rel=1e-8)
    assert dense.iterations == tight.iterations
    _agree(qp, dense, tight, 1e-10, tol_mu)
    rough = _solve("uzawa_auto", qp, operator="matrix_free")
    assert rough.status == Status.SOLVED
    assert dense.info["r"] * 0.95 <= rough.info["r"] <= dense.info["r"] * (1 + 1e-10)
    assert rough.info["mu_min_applications"] > 0 and "Lanczos" in rough.info["mu_min_method"]
    _agree(qp, dense, rough, 1e-10, tol_mu)


@pytest.mark.parametrize("delta", [1e-5, 1e-9])
def test_penalty_matrix_free_agrees(delta):
    qp = cracks(delta)
    dense = _solve("penalty", qp, operator="dense")
    free = _solve("penalty", qp, operator="matrix_free")
    assert dense.status == free.status == Status.SOLVED
    assert dense.iterations["continuation"] == free.iterations["continuation"]
    assert free.info["rho"] == dense.info["rho"]
    _agree(qp, dense, free, 1e-10)
    assert free.info["penetration"] == pytest.approx(dense.info["penetration"], rel=1e-8)
    assert free.info["newton_analyses"] == newton_analyses(free.info)


def test_never_skipped_above_the_dense_sizes(monkeypatch):
    """Above the dense limit (forced small here) operator=auto switches to matrix_free: the paper's
    uzawa, uzawa_auto and penalty run and solve; only an explicit operator=dense is refused."""
    import dualfem.numerics.linalg as linalg
    import dualfem.numerics.operator_choice as operator_choice

    qp = cracks(1e-5)
    monkeypatch.setattr(linalg, "MAX_LOCAL", 10)
    monkeypatch.setattr(operator_choice, "CROSSOVER_LOCAL", 10)
    assert qp.local_dofs.size > 10
    for name in ("uzawa", "uzawa_auto", "penalty"):
        s = solvers()[name]()
        assert s.skip(qp) is None
        s.setup(qp)
        sol = s.solve()
        assert sol.status == Status.SOLVED, (name, sol.message)
        assert sol.info["operator"] == "matrix_free"
        assert solvers()[name](operator="dense").skip(qp)


def test_newton_matrix_analyzed_once():
    """One analysis whatever the coefficients (PARDISO: one for all its kept factors; another backend: one
    per slot, here keep = 3); one numeric factorization per new coefficient vector; a kept one is reused;
    the matrix is K + B' diag(c) B with zeros kept on the pattern."""
    qp = cracks(1e-5)
    nm = NewtonMatrix(qp.K, qp.B, keep=3)
    rng = np.random.default_rng(0)
    cs = [np.where(rng.random(qp.m) < 0.5, 1e6 * rng.random(qp.m), 0.0) for _ in range(3)] + [np.zeros(qp.m)]
    b = rng.standard_normal(qp.n)
    for i in (0, 1, 0, 2, 1, 3, 3):
        H = (qp.K + qp.B.T @ sp.diags(cs[i]) @ qp.B).tocsr()
        assert abs(nm.matrix(cs[i]) - H).max() <= 1e-12 * abs(H).max()
        x = nm.solve(cs[i], b)
        assert np.abs(H @ x - b).max() <= 1e-9 * np.abs(b).max() * abs(H).max() / abs(qp.K).max()
    assert nm.matrix(cs[3]).nnz == nm.nnz == nm.matrix(cs[0]).nnz
    c = nm.counters
    assert c.analyses == (1 if nm.backend.name == "pardiso" else 3)
    assert c.factorizations == 4 and c.reuses == 3 and c.solves == 7


def test_uzawa_factorizations_are_distinct_active_sets():
    """uzawa's matrix-free path factorizes once per distinct active set (as many as the dense path's
    Cholesky factors of the capacitance matrix), after one analysis."""
    qp = cracks(1e-5)
    dense = _solve("uzawa", qp, operator="dense")
    free = _solve("uzawa", qp, operator="matrix_free", keep_factors=64)
    assert free.info["newton_analyses"] == newton_analyses(free.info)
    assert free.info["factorizations"] == free.info["newton_factorizations"] == dense.info["factorizations"]
