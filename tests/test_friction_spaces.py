"""The frictional modified Lagrangian's pieces (dualfem.numerics.friction_spaces): the Armijo remainder equals
psi(a + e) - psi(a) - psi'(a) e on every piece, and the generalized Hessian (rotated rows of slipping 3D nodes)
is the derivative of the gradient; the dense Woodbury solve equals a direct solve."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from dualfem.core.constraints import Constraint
from dualfem.core.laws import Tresca
from dualfem.core.qp import QP
from dualfem.numerics.friction_spaces import Layout, newton_terms, project, remainder

RNG = np.random.default_rng(3)


def tiny(components: int) -> QP:
    n, nodes = 8, 3
    M = RNG.standard_normal((n, n))
    K = M @ M.T + n * np.eye(n)
    B = sp.csr_matrix(RNG.standard_normal((nodes, n)))
    Gt = sp.csr_matrix(RNG.standard_normal((nodes * components, n)))
    w = RNG.uniform(0.5, 1.5, nodes)
    block = Constraint.make(Gt, np.repeat(w, components), Tresca(RNG.uniform(0.5, 1.0, nodes), components))
    return QP(K=sp.csr_matrix(K), F=RNG.standard_normal(n), B=B, weights=w, blocks=(block,), name="tiny")


def penalty(lay: Layout, a: np.ndarray, g) -> float:
    """sum_rows w phi(a): normal (a^+)^2, friction nodes psi(a) = |a|^2 - dist(a, disc)^2 (per node)."""
    total = float(lay.w[lay.normal] @ np.maximum(a[lay.normal], 0.0) ** 2)
    for j in range(len(lay.fric)):
        aj, wj = lay.nodes(a, j), lay.nodes(lay.w, j)[:, 0]
        n = np.linalg.norm(aj, axis=1)
        total += float(wj @ np.where(n <= g[j], n * n, 2 * g[j] * n - g[j] ** 2))
    return total


@pytest.mark.parametrize("components", [1, 2])
@pytest.mark.parametrize("scale", [0.1, 1.0, 3.0])
def test_remainder_is_the_linearization_error(components, scale):
    lay = Layout(tiny(components))
    g = lay.bounds(np.zeros(lay.m))
    for _ in range(20):
        a, e = RNG.standard_normal(lay.m), scale * RNG.standard_normal(lay.m)
        direct = penalty(lay, a + e, g) - penalty(lay, a, g) - 2 * float((lay.w * project(lay, a, g)) @ e)
        assert float(lay.w @ remainder(lay, a, e, g)) == pytest.approx(direct, rel=1e-10, abs=1e-12)


@pytest.mark.parametrize("components", [1, 2])
def test_the_generalized_hessian_is_the_derivative_of_the_gradient(components):
    from dualfem.numerics.friction_spaces import _rotation

    qp = tiny(components)
    lay, r = Layout(qp), 2.0
    G, K = qp.G.toarray(), qp.K.toarray()
    y = RNG.standard_normal(lay.m)
    g = lay.bounds(y)

    def grad(z):
        return K @ z - qp.F - G.T @ (lay.w * project(lay, y - r * G @ z, g))

    z, d = RNG.standard_normal(qp.n), RNG.standard_normal(qp.n)
    coef, rot = newton_terms(lay, y - r * G @ z, g, r)
    Gr = G if rot is None else _rotation(lay, rot) @ G
    H = K + Gr.T @ np.diag(coef) @ Gr
    h = 1e-6
    fd = (grad(z + h * d) - grad(z - h * d)) / (2 * h)
    assert np.allclose(fd, H @ d, rtol=1e-6, atol=1e-6 * np.abs(H @ d).max())


@pytest.mark.parametrize("components", [1, 2])
def test_the_sparse_newton_solve_is_the_rotated_newton_matrix(components):
    """SparseFrictionSpace writes each rotated node's 2 x 2 block on its rows plus one extra row (one pattern):
    its solve equals the direct solve with K + Gr' diag(coef) Gr."""
    from dualfem.numerics.friction_spaces import SparseFrictionSpace, _rotation

    qp = tiny(components)
    lay, r = Layout(qp), 3.0
    space = SparseFrictionSpace(qp, lay)
    G, K = qp.G.toarray(), qp.K.toarray()
    for _ in range(3):
        a = 2 * RNG.standard_normal(lay.m)
        coef, rot = newton_terms(lay, a, lay.bounds(np.zeros(lay.m)), r)
        Gr = G if rot is None else _rotation(lay, rot) @ G
        rhs = RNG.standard_normal(qp.n)
        assert np.allclose(space.newton(coef, rot, rhs), np.linalg.solve(K + Gr.T @ np.diag(coef) @ Gr, rhs),
                           rtol=1e-10, atol=1e-12)
