"""The friction block of a cut mesh (dualfem.problems._friction): its operator is the interface's tangential
jump operator, node-major, and a Tresca-frictional closed crack solved by an independent conic solver (cvxpy,
the friction term as a norm) slips by the closed form 4 (1 - nu^2) (tau - g) / E sqrt(a^2 - x^2)."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.laws import Coulomb, Tresca
from dualfem.problems._friction import friction_block, with_friction

pytest.importorskip("gmsh")

E, NU, A, TAU, G = 1000.0, 0.3, 0.05, 0.3, 0.1


@pytest.fixture(scope="module")
def crack():
    from dualfem.problems.thin_defect import ThinDefect

    return ThinDefect(mesh="gmsh", mesh_size=0.05, tip_size=0.002, E=E, nu=NU, delta=1e3,
                      defects=[{"points": [[0.5 - A, 0.5], [0.5 + A, 0.5]]}],
                      remote_stress=[[-1.0, TAU], [TAU, -1.0]]).build()


def test_the_block_is_the_tangential_jumps_node_major(crack):
    part = crack.interface
    b = friction_block(part, crack.n, "tresca", G)
    J = part.jump_operator(crack.n)
    assert isinstance(b.law, Tresca) and b.m == part.m and np.array_equal(b.weights, part.weights)
    assert abs(b.G - J[part.m:2 * part.m]).max() == 0.0
    c = friction_block(part, crack.n, "coulomb", 0.4, rows=[1, 3])
    assert isinstance(c.law, Coulomb) and c.m == 2 and list(c.law.normal_rows) == [1, 3]
    x = np.random.default_rng(0).standard_normal(crack.n)
    assert np.allclose(c.G @ x, part.jumps(x)[1][[1, 3], 0])


def test_refusals():
    from dualfem.core.errors import InputError
    from dualfem.core.qp import QP

    with pytest.raises(InputError, match="friction must be one of"):
        friction_block(None, 3, "stick", 1.0)
    with pytest.raises(InputError, match="no interface part"):
        with_friction(QP(K=np.eye(2), F=np.zeros(2), B=np.zeros((0, 2))), "tresca", 1.0)


def test_tresca_slip_against_the_closed_form(crack):
    cp = pytest.importorskip("cvxpy")
    qp = with_friction(crack, "tresca", G)
    b = qp.blocks[0]
    x = cp.Variable(qp.n)
    energy = 0.5 * cp.quad_form(x, cp.psd_wrap(qp.K)) - qp.F @ x + cp.sum(cp.multiply(G * b.weights, cp.abs(b.G @ x)))
    cp.Problem(cp.Minimize(energy), [qp.B @ x >= 0]).solve(solver="CLARABEL")
    normal, slip = qp.interface.jumps(x.value)
    xs = qp.interface.s - A
    exact = 4 * (1 - NU ** 2) * (TAU - G) / E * np.sqrt(np.maximum(A ** 2 - xs ** 2, 0.0))
    inner = np.abs(xs) <= 0.8 * A
    err = np.linalg.norm(slip[inner, 0] - exact[inner]) / np.linalg.norm(exact[inner])
    assert err < 0.08                                     # 16 pairs: 5.0 %; frictionless slip would be 50 % larger
    assert np.abs(normal).max() < 0.02 * exact.max()      # closed under compression


def test_the_certificate_forms_the_delassus_matrix_from_the_reduction(crack):
    """faces.delassus: G_I S^-1 G_I' from the local reduction equals the row-by-row K-solves (and costs none)."""
    from dualfem.numerics.faces import delassus
    from dualfem.numerics.ksolver import KSolver

    qp = with_friction(crack, "tresca", G)
    ks = KSolver(qp)
    assert getattr(ks, "red", None) is not None
    fast, _ = delassus(qp, ks)

    class RowByRow:                  # the same K-solves without the reduction's attributes
        def __call__(self, r):
            return ks(r)
    slow, _ = delassus(qp, RowByRow())
    assert fast.shape == (qp.m_total, qp.m_total)
    assert np.abs(fast - slow).max() <= 1e-10 * np.abs(slow).max()
