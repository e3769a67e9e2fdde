"""mprgp on the shared dual operator (solvers/mprgp.py, dualfem/numerics/dual_operator.py) and its
preconditioners (dualfem/numerics/dual_precond.py).

The dense and the matrix-free operator give the same answer to 1e-10 (energy norm of x, relative;
multipliers relative to max |mu|) on small scenes; the Dirichlet preconditioner cuts the operator
applications on a many-crack scene; mprgp falls back to matrix_free when the dense reduction does not
fit; the old spelling operator=matrixfree is accepted; precond=none reproduces the former iterations.
"""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.registry import solvers
from dualfem.core.scene import build_qp, load_scene
from dualfem.core.solution import Status
from dualfem.experiments.runner import make_solver
from dualfem.numerics import linalg, operator_choice
from dualfem.numerics.dual_precond import PRECONDS, defect_clusters, dirichlet_inverse, lumped_inverse

_QP: dict = {}


def f2(N: int, delta: float):
    key = ("f2", N, delta)
    if key not in _QP:
        _QP[key] = build_qp(load_scene("f2", {"N": N, "delta": delta}))
    return _QP[key]


def many_cracks(rows: int = 3, h: float = 0.02, delta: float = 1e-5):
    """A staggered grid of rows x rows short straight cracks in the unit square (gmsh, load f1)."""
    key = ("cracks", rows, h, delta)
    if key not in _QP:
        rng = np.random.default_rng(1)
        length = 0.5 / rows
        defects = []
        for i in range(rows):
            for j in range(rows):
                cx, cy = (j + 0.5) / rows, 0.05 + 0.9 * (i + 0.5) / rows
                a = rng.uniform(0, np.pi)
                dx, dy = 0.5 * length * np.cos(a), 0.5 * length * np.sin(a)
                defects.append({"points": [[cx - dx, cy - dy], [cx + dx, cy + dy]], "curve": "polyline"})
        _QP[key] = build_qp(load_scene("f1", {"mesh": "gmsh", "mesh_size": h, "tip_size": h, "defects": defects,
                                              "delta": delta}))
    return _QP[key]


def solve(qp, **params):
    s = solvers()["mprgp"](**params)
    assert s.skip(qp) is None
    s.setup(qp)
    sol = s.solve()
    assert sol.status == Status.SOLVED, sol.message
    return sol


def assert_agree(qp, a, b, tol=1e-10):
    dx = a.x - b.x
    assert np.sqrt(dx @ (qp.K @ dx)) <= tol * np.sqrt(a.x @ (qp.K @ a.x))
    scale = max(np.abs(a.multipliers).max(), 1e-300)
    assert np.abs(a.multipliers - b.multipliers).max() <= tol * scale


@pytest.mark.parametrize("N,delta", [(32, 1e-5), (32, 1e-9), (64, 1e-5), (64, 1e-9)])
def test_dense_and_matrix_free_agree_on_f2(N, delta):
    qp = f2(N, delta)
    dense, free = solve(qp, operator="dense"), solve(qp, operator="matrix_free")
    assert dense.info["operator"] == "dense" and free.info["operator"] == "matrix_free"
    assert dense.multipliers.max() > 0
    assert_agree(qp, dense, free)


def test_dense_and_matrix_free_agree_on_many_cracks():
    qp = many_cracks()
    assert qp.m > 50
    dense, free = solve(qp, operator="dense"), solve(qp, operator="matrix_free")
    assert dense.info["precond"] == "none" and free.info["precond"] == "dirichlet"     # precond=auto
    assert (dense.multipliers > 0).sum() > 10
    assert_agree(qp, dense, free)
    # the counters: matrix-free products are K-solves, counted next to MPRGP's own steps
    assert free.info["solves"] >= free.info["applications"] > sum(free.iterations.values())
    assert dense.info["solves"] == 0 and dense.info["applications"] > 0


@pytest.mark.parametrize("precond", PRECONDS)
def test_every_preconditioner_gives_the_same_answer(precond):
    qp = many_cracks()
    ref = solve(qp, operator="dense", precond="none")
    for op in ("dense", "matrix_free"):
        sol = solve(qp, operator=op, precond=precond)
        assert sol.info["precond"] == precond
        assert_agree(qp, ref, sol)


def test_dirichlet_preconditioner_cuts_operator_applications():
    qp = many_cracks(rows=3, h=0.01)
    plain = solve(qp, operator="matrix_free", precond="none")
    pre = solve(qp, operator="matrix_free", precond="dirichlet")
    assert pre.iterations["cg"] < 0.7 * plain.iterations["cg"], (plain.iterations, pre.iterations)
    assert pre.info["applications"] < plain.info["applications"]
    assert pre.info["solves"] < plain.info["solves"]


def test_preconditioners_are_spd_and_per_crack():
    qp = many_cracks()
    ncl, _ = defect_clusters(qp)
    assert ncl == 9                                       # one cluster per crack
    for M in (lumped_inverse(qp), dirichlet_inverse(qp, 4), dirichlet_inverse(qp, 0)):
        A = M.toarray()
        assert np.allclose(A, A.T) and np.linalg.eigvalsh(A).min() > 0
    # layers = 0: no ring around the crack, the Schur complement is K on the crack: the lumped one
    assert np.allclose(dirichlet_inverse(qp, 0).toarray(), lumped_inverse(qp).toarray())


def test_matrix_free_when_dense_does_not_fit(monkeypatch):
    qp = f2(32, 1e-5)
    ref = solve(qp, operator="dense")
    monkeypatch.setattr(operator_choice, "CROSSOVER_LOCAL", 10)
    auto = solve(qp)                                      # operator=auto, the default
    assert auto.info["operator"] == "matrix_free" and "auto" in auto.info["operator_chosen_because"]
    assert_agree(qp, ref, auto)
    monkeypatch.setattr(linalg, "MAX_LOCAL", 10)
    dense = solvers()["mprgp"](operator="dense")
    assert "matrix_free" in dense.skip(qp)                # refused, naming the other operator
    assert_agree(qp, ref, solve(qp, operator="matrix_free"))


def test_old_operator_spelling_is_accepted():
    s = make_solver("mprgp", {"operator": "matrixfree"})
    assert s.params["operator"] == "matrix_free"


def test_precond_none_keeps_the_former_iterations():
    """The dense operator without preconditioner (the default for dense): the former iterations."""
    for params in ({"precond": "none"}, {}):
        sol = solve(f2(32, 1e-5), operator="dense", **params)
        assert sol.iterations == {"cg": 6, "expansion": 1, "proportioning": 1}


def test_dirichlet_blocks_dense_and_sparse_agree(monkeypatch):
    """A long crack's layer is factorized by a sparse LU (DENSE_LAYER): the same blocks."""
    from dualfem.numerics import dual_precond

    qp = f2(32, 1e-5)
    dense = dirichlet_inverse(qp, 4).toarray()
    monkeypatch.setattr(dual_precond, "DENSE_LAYER", 0)
    sparse = dirichlet_inverse(qp, 4).toarray()
    assert np.abs(dense - sparse).max() <= 1e-10 * np.abs(dense).max()


def test_dirichlet_blocks_are_cut_for_long_clusters(monkeypatch):
    """A cluster longer than MAX_BLOCK rows is cut into blocks: still SPD, mprgp gives the same answer."""
    from dualfem.numerics import dual_precond

    qp = f2(32, 1e-5)
    ref = solve(qp, operator="dense", precond="none")
    monkeypatch.setattr(dual_precond, "MAX_BLOCK", 4)
    M = dirichlet_inverse(qp, 4).toarray()
    assert np.allclose(M, M.T) and np.linalg.eigvalsh(M).min() > 0
    assert np.count_nonzero(M) <= 4 * qp.m
    assert_agree(qp, ref, solve(qp, operator="dense", precond="dirichlet"))
