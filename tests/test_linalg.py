"""The local Schur reduction: exact, cached, and its orderings valid."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from dualfem.core.qp import QP
from dualfem.numerics import linalg


@pytest.mark.parametrize("name, delta", [("f2", 1e-5), ("f1", 1e-9), ("f3", 1e-1)])
def test_reduction_is_exact(scene, name, delta):
    _, qp = scene(name, 16, delta)
    red = linalg.LocalReduction(qp)
    x = sla.spsolve(qp.K.tocsc(), qp.F)
    # the Schur complement against a dense reference
    K = qp.K.toarray()
    I = red.I
    R = np.setdiff1d(np.arange(qp.n), I)
    S_ref = K[np.ix_(I, I)] - K[np.ix_(I, R)] @ np.linalg.solve(K[np.ix_(R, R)], K[np.ix_(R, I)])
    assert np.abs(red.S - S_ref).max() <= 1e-9 * np.abs(S_ref).max()
    xI = np.linalg.solve(red.S, red.g)
    assert np.abs(red.full(xI) - x).max() <= 1e-10 * np.abs(x).max()
    assert red.energy(xI) == pytest.approx(qp.energy(x), rel=1e-10)
    assert red.norm2(xI) == pytest.approx(x @ (qp.K @ x), rel=1e-10)
    # K^-1 r for any r, and the reduced dual data D = B K^-1 B', b0 = B K^-1 F
    r = np.random.default_rng(0).standard_normal(qp.n)
    y = sla.spsolve(qp.K.tocsc(), r)
    assert np.abs(red.k_solve(r) - y).max() <= 1e-10 * np.abs(y).max()
    Bd = qp.B.toarray()
    D_ref = Bd @ np.linalg.solve(K, Bd.T)
    D, b0 = red.dual()
    assert np.abs(D - D_ref).max() <= 1e-9 * np.abs(D_ref).max() and np.array_equal(D, D.T)
    assert np.abs(b0 - qp.B @ x).max() <= 1e-10 * np.abs(x).max()
    assert red.dual()[0] is D                                   # computed once
    V = red.half_delassus()                                     # L^-1 B_I' with S = L L': D = V'V
    assert np.abs(np.tril(red.S_cho[0]) @ V - red.BI.T).max() <= 1e-9 * np.abs(red.BI).max()
    assert np.array_equal(V.T @ V, D)


def test_factorization_shared_across_delta_and_load():
    from dualfem.core.scene import load_scene

    problem = load_scene("f2", {"N": 16, "delta": 1e-5})
    a = problem.build()
    b = problem.with_params(load="f1", delta=1e-9).build()      # the same delta-free K_fixed
    store = linalg.FactorStore()
    ra, rb = linalg.LocalReduction(a, store=store), linalg.LocalReduction(b, store=store)
    assert ra.factor is rb.factor and store.factorizations == 1     # one factorization of K_fixed for both
    assert not np.allclose(ra.S, rb.S)      # but the delta part differs


@pytest.mark.parametrize("geometric", [True, False])
def test_orderings_are_permutations_with_local_last(scene, geometric):
    _, qp = scene("f2", 16, 1e-5)
    maps = qp.maps if geometric else {}
    q = QP(K=qp.K, F=qp.F, B=qp.B, weights=qp.weights, K_fixed=qp.K_fixed, local_dofs=qp.local_dofs, maps=maps)
    perm = linalg.ordering(q, q.local_dofs)
    assert np.array_equal(np.sort(perm), np.arange(q.n))
    assert set(perm[-q.local_dofs.size:]) == set(q.local_dofs)


def test_geometric_dissection_beats_natural_fill():
    """On a grid, nested dissection must give far less fill than the natural (banded) order."""
    n = 80
    g = sp.diags([1.0, 1.0, 1.0, 1.0], [-1, 1, -n, n], shape=(n * n, n * n)) + 4 * sp.eye(n * n)
    xy = np.array(np.meshgrid(np.arange(n), np.arange(n))).reshape(2, -1).astype(float)
    xy = xy[::-1]  # node k = (row, col) -> (x = col, y = row)
    perm = linalg.geometric_nested_dissection(xy, g)
    A = g.tocsc()
    nd = sla.splu(A[perm][:, perm].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0)
    nat = sla.splu(A, permc_spec="NATURAL", diag_pivot_thresh=0.0)
    assert nd.L.nnz < 0.5 * nat.L.nnz


def test_generic_qp_without_mesh_maps():
    """A QP with no coordinates still reduces exactly (level-set dissection)."""
    rng = np.random.default_rng(1)
    n = 300
    A = sp.random(n, n, density=0.02, random_state=2)
    K = (A @ A.T + sp.eye(n) * 5).tocsc()
    B = sp.csr_matrix((np.ones(4), (np.arange(4), [3, 50, 120, 299])), shape=(4, n))
    qp = QP(K=K, F=rng.normal(size=n), B=B)
    red = linalg.LocalReduction(qp)
    x = sla.spsolve(K, qp.F)
    assert np.abs(red.full(np.linalg.solve(red.S, red.g)) - x).max() <= 1e-10 * np.abs(x).max()


def test_every_unknown_local(scene):
    """B touching every unknown leaves nothing to dissect: the reduction is then dense K itself."""
    _, qp = scene("f2", 8, 1e-5)
    q = QP(K=qp.K, F=qp.F, B=sp.eye(qp.n, format="csr"), maps=qp.maps)
    red = linalg.LocalReduction(q)
    assert np.allclose(red.S, qp.K.toarray()[np.ix_(red.I, red.I)])
    x = sla.spsolve(qp.K.tocsc(), qp.F)
    assert np.abs(red.full(np.linalg.solve(red.S, red.g)) - x).max() <= 1e-10 * np.abs(x).max()


def test_store_key_follows_the_content_of_K_fixed(scene):
    """A K_fixed changed in place gets a new factorization; frozen (read-only) memory is known by identity
    (no hashing), also through another view of the same memory."""
    import dataclasses

    _, qp = scene("f2", 16, 1e-5)
    store = linalg.FactorStore()
    Kf = qp.K_fixed.copy()                                    # writable: hashed on every call
    q1 = dataclasses.replace(qp, K_fixed=Kf, store=store)
    f1 = linalg.factor_fixed(q1)
    Kf.data *= 2.0
    f2 = linalg.factor_fixed(q1)
    assert f2 is not f1 and np.allclose(f2.S_fixed, 2.0 * f1.S_fixed) and store.factorizations == 2
    assert not store._known                                   # nothing frozen: nothing known by identity
    frozen = qp.K_fixed.copy()
    linalg.freeze(frozen.data, frozen.indices, frozen.indptr)
    with pytest.raises(ValueError):
        frozen.data[0] = 1.0
    q2 = dataclasses.replace(qp, K_fixed=frozen, store=store)
    a = linalg.factor_fixed(q2)
    assert a is not f1 and len(store._known) == 1     # frozen memory of its own: its own entry
    view = sp.csc_matrix((frozen.data, frozen.indices, frozen.indptr), shape=frozen.shape)
    again = dataclasses.replace(qp, K_fixed=view, store=store)
    assert linalg.factor_fixed(again) is a and len(store._known) == 1 and store.factorizations == 3
    store.clear()
    assert len(store) == 0 and not store._known and store.factorizations == 3
