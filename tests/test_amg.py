"""Linear algebra that scales in 3D: the synthetic 3D contact QP, the 3D memory model, K^-1 by
AMG-preconditioned CG (rigid-body modes), the dual solvers on the amg operator, and the certificate
without a factorization of K."""
from __future__ import annotations

import functools
import sys

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import dualfem.numerics.dual_operator as dop
import dualfem.numerics.memory as memory
from dualfem.core.errors import InputError, MissingDependency
from dualfem.experiments.runner import run
from dualfem.numerics.amg import LAMBDA_SAFETY, AmgKSolve, amg_for, inner_rtol, require_pyamg, rigid_body_modes
from dualfem.numerics.certify import KSolver, certified_error
from dualfem.numerics.dual_operator import MatrixFreeDualOperator, choose_operator

pyamg = pytest.importorskip("pyamg")        # the amg extra

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from _three_d_qp import box_qp, elasticity_matrix, unknowns  # noqa: E402


@functools.cache
def _qp(N: int = 8):
    return box_qp(N)


def _energy_rel(qp, x, ref):
    d = x - ref
    return float(np.sqrt(d @ (qp.K @ d) / (ref @ (qp.K @ ref))))


def test_three_d_qp_and_its_assembly():
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    m = skfem.MeshTet.init_tensor(*(np.linspace(0, 1, 4),) * 3)
    basis = skfem.Basis(m, skfem.ElementVector(skfem.ElementTetP1()))
    Ks = skfem.asm(linear_elasticity(*lame_parameters(1000.0, 0.3)), basis)
    Km = elasticity_matrix(np.asarray(m.p, float), np.asarray(m.t), 1000.0, 0.3)
    P = basis.nodal_dofs.T.ravel()                        # node-major (ours) -> scikit-fem's numbering
    assert abs(Ks[P][:, P] - Km).max() <= 1e-12 * abs(Km).max()
    qp = _qp()
    g = qp.geometry
    assert qp.n == unknowns(8) and g.dim == 3 and g.nodes.shape[0] == 3 and g.cells.shape[0] == 4
    assert g.node_dofs.shape == (3, g.nodes.shape[1]) and (g.node_dofs[:, g.nodes[2] == 0] == -1).all()
    assert qp.m == 81 and np.isclose(qp.weights.sum(), 1.0)


def test_rigid_body_modes_span_the_kernel():
    qp = _qp()
    X = qp.geometry.nodes
    Kfree = elasticity_matrix(X, qp.geometry.cells, 1000.0, 0.3)       # no clamp: the rigid motions are free
    free_all = type(qp.geometry).make(X, qp.geometry.cells, np.arange(3 * X.shape[1]).reshape(-1, 3).T)
    M = rigid_body_modes(free_all, Kfree.shape[0])
    assert M.shape == (Kfree.shape[0], 6) and np.linalg.matrix_rank(M) == 6
    assert np.abs(Kfree @ M).max() <= 1e-10 * abs(Kfree).max() * np.abs(M).max()
    Mc = rigid_body_modes(qp.geometry, qp.n)                          # clamped: restricted to the unknowns
    assert Mc.shape == (qp.n, 6) and np.abs(Kfree @ M).max() < np.abs(qp.K @ Mc).max()
    X2 = np.random.default_rng(0).random((2, 5))                      # 2D: 3 modes
    g2 = type(qp.geometry).make(X2, np.array([[0], [1], [2]]), np.arange(10).reshape(-1, 2).T)
    assert rigid_body_modes(g2, 10).shape == (10, 3)


def test_amg_solve_residuals_warm_start_block_and_lambda():
    qp = _qp()
    a = AmgKSolve(qp.K, rigid_body_modes(qp.geometry, qp.n))
    exact = spla.spsolve(qp.K.tocsc(), qp.F)
    z = a.solve(qp.F, rtol=1e-10)
    assert a.last_rel[0] <= 1e-10 and np.isclose(a.last_abs[0], np.linalg.norm(qp.F - qp.K @ z))
    assert _energy_rel(qp, z, exact) < 1e-8
    its = a.counters.iterations
    a.solve(qp.F, x0=exact, rtol=1e-10)                     # warm start at the answer: no iteration
    assert a.counters.iterations == its
    R = np.column_stack([qp.F, qp.K @ np.ones(qp.n)])
    Z = a.solve(R, rtol=1e-12)
    assert Z.shape == R.shape and np.allclose(Z[:, 1], 1.0, rtol=0, atol=1e-9)
    lam_true = spla.eigsh(qp.K.tocsc(), k=1, sigma=0, which="LM", return_eigenvectors=False)[0]
    assert lam_true / LAMBDA_SAFETY * 0.99 <= a.lambda_min() <= lam_true / LAMBDA_SAFETY * 1.01
    assert a.energy_error(1e-3) == pytest.approx(1e-3 / np.sqrt(a.lambda_min()))
    assert inner_rtol(1e-9) == pytest.approx(1e-12) and inner_rtol(1.0) == 1e-8 and inner_rtol(1e-20) == 1e-13


def test_missing_pyamg_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyamg", None)
    with pytest.raises(MissingDependency, match=r"dualfem\[amg\]"):
        require_pyamg()


def test_memory_model_knows_the_dimension():
    n = 670_000
    assert memory.factor_bytes(n, dim=3) > 5 * memory.factor_bytes(n, dim=2)
    for nn, nnz in memory.CALIBRATION_3D:
        assert 0.75 < memory.nnz_l(nn, 3) / nnz < 1.33
    assert memory.amg_bytes(20_000) < memory.factor_bytes(20_000, dim=3)       # amg is the cheaper from ~7 k
    assert not memory.fits(n, "pardiso", limit_bytes=16 * 2**30, dim=3)[0]     # the factor does not fit
    assert memory.fits(n, "amg", limit_bytes=16 * 2**30, dim=3)[0]             # one AMG hierarchy does
    assert memory.fits(n, "pardiso", limit_bytes=16 * 2**30, dim=2)[0]         # in 2D the same n factors
    with pytest.raises(InputError, match="dim"):
        memory.factor_bytes(n, dim=4)


def test_auto_takes_amg_when_no_factorization_fits(monkeypatch):
    # the models cross at ~7 k unknowns (a 3D factor ~ n^1.42, the hierarchy ~ n): at 6,084 unknowns the AMG
    # estimate is lowered a little so that it is the cheaper one, as it is from ~7 k unknowns on
    monkeypatch.setattr(memory, "AMG_BYTES_PER_UNKNOWN", 1024)
    qp = _qp(12)
    est = dop.estimates(qp)
    assert est["amg"] < est["matrix_free"] < est["dense"]
    assert choose_operator(qp, "auto", limit_bytes=est["dense"] + 1)[0] == "dense"
    assert choose_operator(qp, "auto", limit_bytes=(est["amg"] + est["matrix_free"]) // 2)[0] == "amg"
    with pytest.raises(InputError, match="operator=matrix_free.*operator=amg"):
        choose_operator(qp, "matrix_free", limit_bytes=(est["amg"] + est["matrix_free"]) // 2)
    with pytest.raises(InputError, match="neither operator fits"):
        choose_operator(qp, "auto", limit_bytes=est["amg"] // 2)
    # a 2D-calibrated model would have taken the factorization: the 3D one is larger
    assert est["matrix_free"] > memory.SAFETY * memory.factor_bytes(qp.n, dim=2)


def test_amg_operator_matches_the_factorization():
    qp = _qp()
    f, a = MatrixFreeDualOperator(qp), MatrixFreeDualOperator(qp, ksolve="amg", k_rtol=1e-12)
    v = np.random.default_rng(1).standard_normal((qp.m, 2))
    assert np.abs(a.apply(v) - f.apply(v)).max() <= 1e-9 * np.abs(f.apply(v)).max()
    assert np.abs(a.b0 - f.b0).max() <= 1e-9 * np.abs(f.b0).max()
    mu = np.abs(v[:, 0])
    assert _energy_rel(qp, a.x_of(mu), f.x_of(mu)) < 1e-9
    assert a.accuracy == 1e-12 and f.accuracy == 0.0 and a.info()["ksolve"] == "amg"
    assert a.counters.factorizations == 0 and a.counters.amg_iterations > 0
    assert amg_for(qp) is a.fact                  # one hierarchy per QP, kept in its store


@pytest.mark.parametrize("solver", ["pdas", "mprgp", "uzawa_auto", "uzawa", "penalty"])
def test_dual_solvers_on_the_amg_operator_agree_with_the_dense_path(solver):
    qp = _qp()
    ref = run("pdas", qp, {"operator": "dense"})
    s = run(solver, qp, {"operator": "amg"})
    assert str(s.status) == "solved", s.message
    assert s.info["operator"] == "matrix_free" and s.info["ksolve"] == "amg"
    if solver in ("uzawa", "penalty"):            # their Newton systems are AMG-CG solves too
        assert s.info["newton_backend"] == "amg" and s.info["newton_analyses"] == 0
    tol = {"uzawa": 1e-6, "penalty": 1e-8}.get(solver, 1e-9)     # the declared tolerances
    assert _energy_rel(qp, s.x, ref.x) < tol
    # the contact set is a proper subset of the top nodes
    assert 0 < int((ref.multipliers > 0).sum()) < qp.m


def test_certificate_without_a_factorization():
    qp = _qp()
    s = run("pdas", qp, {"operator": "dense"})
    dense = certified_error(qp, s.x, s.multipliers, KSolver(qp))
    ks = KSolver(qp, ksolve="amg")
    assert ks.amg and ks.delassus() is None and ks.op.fact is amg_for(qp)     # the shared hierarchy
    c = certified_error(qp, s.x, s.multipliers, ks)
    assert c["value"] < 1e-9 and abs(c["active_set"] - dense["active_set"]) < 1e-10
    assert c["multipliers"] < 1e-9
    # the widening: the recorded true residuals of the K-solves enter as (estimated) energy-norm errors,
    # included in the value (2 e_K / |x|_K: two solves of the step)
    e_K, e_2 = ks.k_error()
    assert e_K > 0 and e_2 > 0 and 2 * e_K / np.sqrt(s.x @ (qp.K @ s.x)) <= c["active_set"]
    # deliberately wrong answers are refused: a scaled x, a shifted contact force
    x2 = s.x * (1 + 1e-6)
    bad = certified_error(qp, x2, s.multipliers, ks)["value"]
    assert bad == pytest.approx(certified_error(qp, x2, s.multipliers, KSolver(qp))["value"], rel=1e-3)
    assert bad > 5e-7
    mu2 = s.multipliers.copy()
    mu2[np.argmax(mu2)] *= 1.01
    worse = certified_error(qp, s.x, mu2, ks)
    assert not (worse["value"] <= 1e-9 and worse["multipliers"] <= 1e-9)


def test_runner_certifies_on_amg_when_no_factorization_fits(monkeypatch):
    monkeypatch.setattr(memory, "AMG_BYTES_PER_UNKNOWN", 1024)        # as in the test above
    qp = box_qp(10)
    est = dop.estimates(qp)
    monkeypatch.setattr(memory, "available_bytes", lambda: (est["amg"] + est["matrix_free"]) // 2)
    s = run("pdas", qp, {})
    assert str(s.status) == "solved", s.message
    assert s.info["ksolve"] == "amg" and "no factorization" in s.info["operator_chosen_because"]
    assert s.info["certificate"]["value"] < 1e-9
    assert "lambda_min" in amg_for(qp).counters.time_s       # the certificate's AMG error terms were formed
    wrong = run("pdas", qp, {"operator": "amg", "max_iter": 1})       # one Newton step: not the answer
    assert str(wrong.status) != "solved"


def test_newton_matrix_by_amg():
    from dualfem.numerics.newton_matrix import NewtonMatrix

    qp = _qp()
    c = np.where(np.arange(qp.m) % 2 == 0, 1e4, 0.0)
    nm = NewtonMatrix(qp.K, qp.B, "amg", modes=rigid_body_modes(qp.geometry, qp.n), rtol=1e-12)
    H = (qp.K + qp.B.T @ sp.diags(c) @ qp.B).tocsc()
    z = nm.solve(c, qp.F)
    assert _energy_rel(qp, z, spla.spsolve(H, qp.F)) < 1e-8
    nm.solve(c, qp.F)
    assert nm.counters.factorizations == 1 and nm.counters.reuses == 1 and nm.info()["newton_backend"] == "amg"


def test_check_fits_before_assembly_knows_3d_and_amg():
    class Scene:
        dim = 3

        def size_estimate(self):
            return 670_000, "a 3D scene"

    memory.check_fits(Scene(), max_bytes=16e9)            # the factor does not fit, one AMG hierarchy does
    with pytest.raises(InputError, match="a 3D scene"):
        memory.check_fits(Scene(), max_bytes=2e9)         # neither
    Scene.dim = 2
    memory.check_fits(Scene(), max_bytes=16e9)            # 2D: the factorization fits


def test_full_space_newton_by_amg_is_certified():
    from dualfem.numerics.amg import full_space_newton

    qp = _qp()
    ref = run("pdas", qp, {"operator": "dense"})
    r = full_space_newton(qp)
    assert r.converged and r.message == "active set settled", r.message
    assert 1 <= r.newton_steps <= 10 and r.hierarchies == r.newton_steps and r.al_steps >= r.newton_steps
    assert _energy_rel(qp, r.x, ref.x) < 1e-10
    assert np.abs(r.mu - ref.multipliers).max() < 1e-9 * np.abs(ref.multipliers).max()
    c = certified_error(qp, r.x, r.mu, KSolver(qp, ksolve="amg"))
    assert c["value"] < 1e-9 and c["multipliers"] < 1e-9
    capped = full_space_newton(qp, max_newton=1)          # one step is not the answer here: said so
    assert not capped.converged and "no convergence" in capped.message


@pytest.mark.parametrize("delta", [1e-5, 1e-9])
def test_full_space_newton_on_a_2d_scene(delta):
    from dualfem.core.scene import load_scene
    from dualfem.numerics.amg import full_space_newton

    qp = load_scene("f2", {"N": 32, "delta": delta}).build()      # 3 rigid modes from the 2D geometry
    r = full_space_newton(qp)
    ref = run("pdas", qp, {"operator": "dense"})
    assert r.converged and _energy_rel(qp, r.x, ref.x) < 1e-9
    assert certified_error(qp, r.x, r.mu, KSolver(qp, ksolve="amg"))["value"] < 1e-9


def test_operator_amg_without_pyamg_is_a_skip_naming_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyamg", None)
    s = run("pdas", _qp(), {"operator": "amg"})
    assert str(s.status) == "skipped" and "dualfem[amg]" in s.message
