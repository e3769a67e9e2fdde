"""The Coulomb fixed point over Tresca solves (dualfem.numerics.coulomb): converges to the closed form on a
one-node spring and on a closed inclined crack (certified by the judge), mu_f = 0 is the frictionless answer,
and a cycling fixed point stops as stalled with status max_iter, never solved."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from dualfem.core.constraints import Constraint
from dualfem.core.errors import InputError
from dualfem.core.laws import Coulomb, Tresca
from dualfem.core.qp import QP
from dualfem.numerics.coulomb import coulomb_fixed_point, thresholds, tresca_qp

pytest.importorskip("cvxpy")
from _tresca_ref import tresca_reference  # noqa: E402


def spring(coefficient, c=0.0, kn=100.0, kt=1.0, p=1.0, tau=1.0, w=0.5):
    """One contact node: unknowns (normal, tangential jump), normal load -p, shear tau, coupling c."""
    K = np.array([[kn, c], [c, kt]])
    block = Constraint.make(sp.csr_matrix([[0.0, 1.0]]), [w], Coulomb(coefficient))
    return QP(K=sp.csr_matrix(K), F=np.array([-p, tau]), B=sp.csr_matrix([[1.0, 0.0]]), weights=np.array([w]),
              blocks=(block,), name="spring")


def test_one_node_slips_by_the_closed_form_and_reports_its_counters():
    res = coulomb_fixed_point(spring(0.4), tresca_reference, tol=1e-8, max_iter=10)
    assert res.status == "solved" and not res.stalled and res.iterations == 2      # g: 0 -> 0.4 p / w, then fixed
    assert res.x == pytest.approx([0.0, 1.0 - 0.4], abs=1e-8)                      # u_t = (tau - mu_f p) / kt
    assert res.mu == pytest.approx([1.0, -0.4], abs=1e-8)                          # lambda = p, mu_t = -mu_f p
    assert res.threshold[0] == pytest.approx([0.4 / 0.5])
    assert res.counters["solves"] == 2
    s = res.summary()
    assert s == {"coulomb_iterations": 2, "coulomb_stalled": 0} and res.details()["coulomb_change"] <= 1e-8


def test_coupled_node_converges_with_the_observed_contraction():
    # lambda = p + c u_t, u_t = (tau - mu_f lambda) / kt: the fixed point contracts by c mu_f / kt = 0.2
    res = coulomb_fixed_point(spring(0.4, c=0.5), tresca_reference, tol=1e-10, max_iter=40)
    lam = (1.0 + 0.5 * 1.0) / (1 + 0.5 * 0.4)
    assert res.status == "solved" and res.mu[0] == pytest.approx(lam, rel=1e-8)
    assert np.median(res.contractions) == pytest.approx(0.2, rel=1e-3)


def test_a_cycling_fixed_point_is_stalled_not_solved():
    # c mu_f / kt = 1.5 > 1: lambda = 1 (stick) -> 2.5 (slip) -> 1 ... around the solution lambda = 1.6
    res = coulomb_fixed_point(spring(0.5, c=3.0), tresca_reference, tol=1e-10, max_iter=30, stall=3, relax=1.0)
    assert res.status == "max_iter" and res.stalled and res.iterations < 30
    capped = coulomb_fixed_point(spring(0.5, c=3.0), tresca_reference, tol=1e-10, max_iter=2)
    assert capped.status == "max_iter" and capped.iterations == 2 and not capped.stalled
    # the default relaxation halves omega while the change does not fall: it reaches lambda = 1.6
    relaxed = coulomb_fixed_point(spring(0.5, c=3.0), tresca_reference, tol=1e-8, max_iter=60)
    assert relaxed.status == "solved" and relaxed.relax < 1.0 and relaxed.mu[0] == pytest.approx(1.6, rel=1e-6)


def test_tresca_qp_keeps_the_layout_and_thresholds_read_the_normal_force():
    qp = spring(0.4)
    t = tresca_qp(qp, (np.array([0.8]),))
    law = t.blocks[0].law
    assert isinstance(law, Tresca) and law.radius(t.blocks[0].weights) == pytest.approx([0.4])
    assert t.m_total == qp.m_total and t.G.shape == qp.G.shape
    assert thresholds(qp, np.array([2.0, 0.0]))[0] == pytest.approx([0.4 * 2.0 / 0.5])
    assert thresholds(qp, np.array([-2.0, 0.0]))[0] == pytest.approx([0.0])   # no pressure, no friction


def test_refusals():
    plain = QP(K=sp.eye(2, format="csr"), F=np.zeros(2), B=sp.csr_matrix([[1.0, 0.0]]))
    with pytest.raises(InputError, match="no Coulomb block"):
        coulomb_fixed_point(plain, tresca_reference)
    with pytest.raises(InputError, match="tol must be > 0"):
        coulomb_fixed_point(spring(0.4), tresca_reference, tol=0.0)


E, NU, A, TAU, MU_F = 1000.0, 0.3, 0.05, 0.3, 0.2


@pytest.fixture(scope="module")
def crack():
    pytest.importorskip("gmsh")
    from dualfem.problems.thin_defect import ThinDefect

    return ThinDefect(mesh="gmsh", mesh_size=0.05, tip_size=0.002, E=E, nu=NU, delta=1e3,
                      defects=[{"points": [[0.5 - A, 0.5], [0.5 + A, 0.5]]}],
                      remote_stress=[[-1.0, TAU], [TAU, -1.0]]).build()


def test_closed_crack_coulomb_slip_by_the_closed_form_certified(crack):
    from dualfem.core.solution import Solution, Status
    from dualfem.problems._friction import with_friction
    from dualfem.verify import judge

    qp = with_friction(crack, "coulomb", MU_F)
    res = coulomb_fixed_point(qp, tresca_reference, tol=1e-5, max_iter=30)
    assert res.status == "solved" and 2 <= res.iterations <= 8                # measured: 5, contraction ~0.01
    assert max(res.contractions) < 0.1 and res.summary()["coulomb_iterations"] == res.iterations
    normal, slip = qp.interface.jumps(res.x)
    xs = qp.interface.s - A
    exact = 4 * (1 - NU ** 2) * (TAU - MU_F * 1.0) / E * np.sqrt(np.maximum(A ** 2 - xs ** 2, 0.0))
    inner = np.abs(xs) <= 0.8 * A
    assert np.linalg.norm(slip[inner, 0] - exact[inner]) / np.linalg.norm(exact[inner]) < 0.1
    sol = Solution("fixed_point", Status.SOLVED, x=res.x, multipliers=res.mu)
    assert judge(qp, sol, 1e-5).status == "solved"
    # mu_f = 0: one Tresca solve with g = 0, the frictionless answer
    zero = coulomb_fixed_point(with_friction(crack, "coulomb", 0.0), tresca_reference, tol=1e-8)
    x0, mu0, _ = tresca_reference(crack)
    assert zero.iterations == 1 and zero.status == "solved"
    assert np.abs(zero.x - x0).max() <= 1e-5 * np.abs(x0).max()          # the conic reference's accuracy (g = 0 norms)
    assert np.abs(zero.mu[crack.m:]).max() <= 1e-9 * np.abs(mu0).max()

