"""The dual operator D = B K^-1 B' behind one interface: dense and matrix-free agree; auto's choice;
refusals by memory; pdas and the certificate on both operators give the same answers."""
from __future__ import annotations

import numpy as np
import pytest
from _backend import newton_analyses

import dualfem.numerics.dual_operator as dop
import dualfem.numerics.operator_choice as operator_choice
from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene
from dualfem.experiments.runner import run
from dualfem.numerics.certify import KSolver, certified_error
from dualfem.numerics.dual_operator import DenseDualOperator, MatrixFreeDualOperator, choose_operator, make_operator


def _qp(delta=1e-5, N=32, load="f2"):
    return load_scene(load, {"N": N, "delta": delta}).build()


def _rel(a, b):
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


@pytest.mark.parametrize("delta", [1e-1, 1e-9])
def test_dense_and_matrix_free_agree(delta):
    qp = _qp(delta)
    d, f = DenseDualOperator(qp), MatrixFreeDualOperator(qp)
    rng = np.random.default_rng(0)
    v = rng.standard_normal(qp.m)
    V = rng.standard_normal((qp.m, 3))
    assert _rel(f.b0, d.b0) < 1e-10
    assert _rel(f.apply(v), d.apply(v)) < 1e-10
    assert _rel(f.apply(V), d.apply(V)) < 1e-10                 # a block: one solve with 3 right-hand sides
    mu = np.abs(v)
    assert _rel(f.x_of(mu), d.x_of(mu)) < 1e-10
    A = np.zeros(qp.m, bool)
    A[::3] = True
    assert _rel(f.face_solve(A, v[A]), d.face_solve(A, v[A])) < 1e-9
    assert f.last_face["iterations"] > 0 and f.last_face["kappa"] >= 1.0
    # the diagonal estimate: exact on the sampled rows, within a factor 2 elsewhere (lumped, calibrated)
    ratio = f.diagonal() / d.diagonal()
    assert 0.5 < ratio.min() and ratio.max() < 2.0
    # counters: one factorization, every product counted (the block as 3), no m x m matrix on the path
    assert f.counters.factorizations == 1 and f.counters.applications >= 5
    assert not any(isinstance(a, np.ndarray) and a.ndim == 2 and a.shape == (qp.m, qp.m) for a in vars(f).values())


def test_auto_choice_and_refusals(monkeypatch):
    qp = _qp()
    assert choose_operator(qp, "auto")[0] == "dense"
    monkeypatch.setattr(operator_choice, "CROSSOVER_LOCAL", 10)
    kind, why = choose_operator(qp, "auto")
    assert kind == "matrix_free" and "local unknowns" in why
    assert choose_operator(qp, "dense")[0] == "dense"            # asked: taken while it fits
    with pytest.raises(InputError) as e:
        choose_operator(qp, "dense", limit_bytes=1000)
    msg = str(e.value)
    assert "operator=dense" in msg and "available" in msg and "operator=matrix_free" in msg and str(qp.n) in msg
    with pytest.raises(InputError, match="neither operator fits"):
        choose_operator(qp, "auto", limit_bytes=1000)
    with pytest.raises(InputError, match="operator"):
        make_operator(qp, "sparse")


def test_auto_never_picks_what_does_not_fit(monkeypatch):
    qp = _qp()
    monkeypatch.setattr(operator_choice, "dense_extra_bytes", lambda n_local, m: 10**10)     # dense blocks of 10 GB
    est = dop.estimates(qp)
    assert est["dense"] > est["matrix_free"] > 0
    kind, _ = choose_operator(qp, "auto", limit_bytes=(est["dense"] + est["matrix_free"]) // 2)
    assert kind == "matrix_free"


@pytest.mark.parametrize("newton", ["cg", "factor"])
@pytest.mark.parametrize("delta", [1e-5, 1e-9])
def test_pdas_same_answer_on_both_operators(delta, newton):
    qp = _qp(delta, N=48)
    a = run("pdas", qp, {"operator": "dense"})
    b = run("pdas", qp, {"operator": "matrix_free", "newton": newton})
    assert str(a.status) == str(b.status) == "solved"
    assert a.info["operator"] == "dense" and b.info["operator"] == "matrix_free"
    dx = a.x - b.x
    assert np.sqrt(dx @ (qp.K @ dx) / (a.x @ (qp.K @ a.x))) < 1e-10
    assert _rel(b.multipliers, a.multipliers) < 1e-10
    assert b.info["applications"] > 0 and b.info["face_method"] == newton
    if newton == "cg":
        assert b.info["cg_iterations"] > 0 and b.info["al_steps"] == 0
    else:                  # one factorization of K + B_A'C B_A per active set, analyzed once
        assert b.info["al_steps"] > 0          # (and a few CG steps in the operator's own representation)
        assert b.info["newton_analyses"] == newton_analyses(b.info) and b.info["newton_factorizations"] >= 1
    assert np.isfinite(b.info["certificate"]["value"]) and b.info["certificate"]["value"] < 1e-9


def test_certificate_matrix_free_equals_dense(monkeypatch):
    qp = _qp(1e-5)
    s = run("pdas", qp, {"operator": "dense"})
    dense = certified_error(qp, s.x, s.multipliers, KSolver(qp))
    monkeypatch.setattr(operator_choice, "CROSSOVER_LOCAL", 0)
    ks = KSolver(qp)
    assert ks.op is not None and ks.delassus() is None
    mf = certified_error(qp, s.x, s.multipliers, ks)
    for k in ("bound", "active_set", "multipliers"):
        assert abs(mf[k] - dense[k]) <= 1e-3 * abs(dense[k]) + 1e-15, k
    # a perturbed answer: both certificates see the same error
    x2 = s.x * (1 + 1e-7)
    e_d = certified_error(qp, x2, s.multipliers, KSolver(qp, reduction=None))["value"]
    e_m = certified_error(qp, x2, s.multipliers, ks)["value"]
    assert e_d == pytest.approx(1e-7, rel=0.1) and e_m == pytest.approx(e_d, rel=1e-6)


def test_pdas_matrix_free_when_dense_does_not_fit(monkeypatch):
    import dualfem.numerics.linalg as linalg

    qp = _qp(1e-5)
    monkeypatch.setattr(dop, "MAX_LOCAL", 10, raising=False)
    monkeypatch.setattr(linalg, "MAX_LOCAL", 10)
    s = run("pdas", qp, {})
    assert str(s.status) == "solved" and s.info["operator"] == "matrix_free"
    sk = run("pdas", qp, {"operator": "dense"})
    assert str(sk.status) == "skipped" and "operator=matrix_free" in sk.message


@pytest.mark.parametrize("solver", ["pdas", "mprgp", "uzawa_auto", "penalty"])
def test_matrix_free_through_the_runner_on_a_gmsh_scene(solver):
    """The runner hands plugins a read-only QP: the matrix-free path (and its preconditioners) must not
    write into it; the answer is certified and equals the dense path's."""
    qp = load_scene("two_defects", {}).build()
    a = run(solver, qp, {"operator": "dense"})
    b = run(solver, qp, {"operator": "matrix_free"})
    assert str(a.status) == str(b.status) == "solved", b.message
    assert b.info["operator"] == "matrix_free"
    dx = a.x - b.x
    assert np.sqrt(dx @ (qp.K @ dx) / (a.x @ (qp.K @ a.x))) < 1e-8


def test_certificate_takes_only_speed_hints_from_the_solver(monkeypatch):
    """A matrix-free solver's diagonal estimate and preconditioner speed the certificate's CG up; a bogus
    preconditioner cannot change what is certified (the certificate equals a fresh one, or is unavailable)."""
    import scipy.sparse as sp

    qp = load_scene("two_defects", {}).build()
    monkeypatch.setattr(operator_choice, "CROSSOVER_LOCAL", 0)
    good = run("pdas", qp, {"operator": "matrix_free"})
    fresh = certified_error(qp, good.x, good.multipliers, KSolver(qp))
    assert good.info["certificate"]["value"] == pytest.approx(fresh["value"], rel=1e-4)

    from dualfem.numerics.certify import OperatorHints

    P = sp.random(qp.m, qp.m, density=0.3, random_state=1, format="csr") * 1e6     # not SPD, not an inverse
    hints = OperatorHints.of(type("Op", (), {"_diag": np.full(qp.m, 1e-30), "face_preconditioner": P})(), qp.m)
    x = good.x * (1 + 1e-7)                          # an answer 1e-7 off: never certified better than that
    c = certified_error(qp, x, good.multipliers, KSolver(qp, reduction=hints))["value"]
    assert not np.isfinite(c) or c == pytest.approx(1e-7, rel=0.05)
    assert certified_error(qp, x, good.multipliers, KSolver(qp))["value"] == pytest.approx(1e-7, rel=0.05)
