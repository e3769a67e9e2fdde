"""pdas and mprgp on frictional cracks (HSW's semismooth Newton, dualfem.numerics.friction_newton; MPGP,
dualfem.numerics.friction_mpgp, with Coulomb by the fixed point dualfem.numerics.coulomb): a closed 2D crack
under compression and shear and a coarse 3D penny crack with Tresca and Coulomb friction. Each answer has
KKT residuals at rounding (the evaluator judges it by the laws), agrees with cvxpy+Clarabel's norm formulation,
g = 0 / mu_f = 0 gives the frictionless answer, a large bound sticks every node exactly (the answer of the
crack held closed and stuck: an equality-constrained solve), and Coulomb's answer is the Tresca answer at its
own threshold mu_f lambda; MPGP without its Newton polish agrees with pdas."""
from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from dualfem.core import evaluator
from dualfem.core.laws import Tresca
from dualfem.experiments.runner import make_solver
from dualfem.problems._friction import with_friction

pytest.importorskip("gmsh")

E, NU, A, TAU = 1000.0, 0.3, 0.05, 0.3


@functools.cache
def crack2d():
    from dualfem.problems.thin_defect import ThinDefect

    return ThinDefect(mesh="gmsh", mesh_size=0.05, tip_size=0.002, E=E, nu=NU, delta=1e3,
                      defects=[{"points": [[0.5 - A, 0.5], [0.5 + A, 0.5]]}],
                      remote_stress=[[-1.0, TAU], [TAU, -1.0]]).build()


@functools.cache
def penny():
    from dualfem.core.scene import load_scene

    return load_scene("penny", {"remote_stress": [[0, 0, 0.3], [0, 0, 0.1], [0.3, 0.1, -1.0]]}).build()


def solve(qp, name="pdas", **params):
    s = make_solver(name, params)
    assert s.skip(qp) is None
    s.setup(qp)
    sol = s.solve()
    assert sol.multipliers.size == qp.m_total                 # every block's multipliers: friction was solved
    return sol


def kkt(qp, sol) -> float:
    return evaluator.kkt_error(evaluator.residuals(qp, sol.x, sol.multipliers))


def mixed_bound(qp, low: float, high: float) -> np.ndarray:
    """A Tresca bound per node: ``high`` on every other node pair, ``low`` elsewhere (stick and slip both)."""
    return np.where(np.arange(qp.interface.m) % 2 == 0, high, low)


def cvxpy_tresca(qp):
    cp = pytest.importorskip("cvxpy")
    b, c = qp.blocks[0], qp.blocks[0].law.components
    r = b.law.radius(b.weights)
    x = cp.Variable(qp.n)
    slips = cp.reshape(b.G @ x, (r.size, c), order="C")
    energy = 0.5 * cp.quad_form(x, cp.psd_wrap(qp.K)) - qp.F @ x + r @ cp.norm(slips, 2, axis=1)
    cp.Problem(cp.Minimize(energy), [qp.B @ x >= 0]).solve(solver="CLARABEL")
    return x.value


SOLVERS = pytest.mark.parametrize("name", ["pdas", "mprgp"])


@SOLVERS
@pytest.mark.parametrize("scene", [crack2d, penny], ids=["2d", "3d"])
def test_tresca_agrees_with_clarabel_and_is_kkt_exact(scene, name):
    qp = scene()
    qp = with_friction(qp, "tresca", mixed_bound(qp, 0.1, 0.6))
    sol = solve(qp, name)
    assert sol.status == "solved" and kkt(qp, sol) < 1e-12
    c = qp.blocks[0].law.components
    slips = np.linalg.norm((qp.blocks[0].G @ sol.x).reshape(-1, c), axis=1)
    assert 0 < (slips > 1e-9 * slips.max()).sum() < slips.size          # both stick and slip nodes
    xr = cvxpy_tresca(qp)                                  # an interior-point answer: ~1e-4 of x here
    assert np.abs(sol.x - xr).max() < 1e-3 * np.abs(xr).max()
    energy = evaluator.residuals(qp, sol.x, sol.multipliers)["energy"]
    assert energy <= evaluator.residuals(qp, xr, sol.multipliers)["energy"] + 1e-12 * abs(energy)


@SOLVERS
@pytest.mark.parametrize("scene", [crack2d, penny], ids=["2d", "3d"])
@pytest.mark.parametrize("kind", ["tresca", "coulomb"])
def test_zero_friction_is_the_frictionless_answer(scene, kind, name):
    qp0 = scene()
    x0 = solve(qp0).x
    sol = solve(with_friction(qp0, kind, 0.0), name)
    assert sol.status == "solved"
    assert np.abs(sol.x - x0).max() <= 1e-12 * np.abs(x0).max()


@SOLVERS
@pytest.mark.parametrize("scene", [crack2d, penny], ids=["2d", "3d"])
@pytest.mark.parametrize("kind, value", [("tresca", 100.0), ("coulomb", 1.0)])
def test_a_large_bound_sticks_every_node_exactly(scene, name, kind, value):
    qp = with_friction(scene(), kind, value)                     # |tau| = 0.3 < mu_f sigma_n = 1: stick
    sol = solve(qp, name)
    assert sol.status == "solved"
    G = qp.G                                                      # stuck and closed: G x = 0, K x - F = G' mu
    KKT = sp.bmat([[qp.K, G.T], [G, None]], format="csc")
    xs = spla.spsolve(KKT, np.r_[qp.F, np.zeros(G.shape[0])])[:qp.n]
    assert np.abs(sol.x - xs).max() <= 1e-10 * np.abs(xs).max()
    assert np.abs(qp.blocks[0].G @ sol.x).max() <= 1e-13 * np.abs(xs).max()


@SOLVERS
@pytest.mark.parametrize("scene", [crack2d, penny], ids=["2d", "3d"])
def test_coulomb_is_tresca_at_its_own_threshold(scene, name):
    qp0 = scene()
    qp = with_friction(qp0, "coulomb", 0.15)
    sol = solve(qp, name)
    assert sol.status == "solved" and kkt(qp, sol) < 1e-12
    b = qp.blocks[0]
    lam = sol.multipliers[:qp0.m]
    w = b.weights[::b.law.components]
    tq = with_friction(qp0, "tresca", 0.15 * np.maximum(lam, 0.0) / w)
    assert isinstance(tq.blocks[0].law, Tresca)
    xt = solve(tq).x
    assert np.abs(sol.x - xt).max() <= 1e-10 * np.abs(xt).max()


def test_slip_by_the_closed_form_2d():
    qp = with_friction(crack2d(), "tresca", 0.1)
    sol = solve(qp)
    normal, slip = qp.interface.jumps(sol.x)
    xs = qp.interface.s - A
    exact = 4 * (1 - NU ** 2) * (TAU - 0.1) / E * np.sqrt(np.maximum(A ** 2 - xs ** 2, 0.0))
    inner = np.abs(xs) <= 0.8 * A
    assert np.linalg.norm(slip[inner, 0] - exact[inner]) / np.linalg.norm(exact[inner]) < 0.08


def test_a_block_that_is_not_friction_is_skipped():
    import dataclasses

    from dualfem.core.constraints import Constraint
    from dualfem.core.laws import SIGNORINI

    qp0 = crack2d()
    extra = Constraint.make(qp0.B, qp0.weights, SIGNORINI)
    qp = dataclasses.replace(qp0, blocks=(extra,), store=None)
    assert "only friction blocks" in make_solver("pdas").skip(qp)


@pytest.mark.parametrize("scene", [crack2d, penny], ids=["2d", "3d"])
def test_mpgp_alone_agrees_with_pdas(scene):
    qp = with_friction(scene(), "tresca", mixed_bound(scene(), 0.1, 0.6))
    a, b = solve(qp), solve(qp, "mprgp", friction_polish=False)
    assert b.status == "solved" and "polish_newton" not in b.iterations and b.iterations["proportioning"] > 0
    assert np.abs(a.x - b.x).max() <= 1e-9 * np.abs(a.x).max()


@SOLVERS
def test_matrix_free_operator_gives_the_dense_answer(name):
    qp = with_friction(crack2d(), "coulomb", 0.15)
    a, b = solve(qp), solve(qp, name, operator="matrix_free")
    assert b.status == "solved" and b.info["operator"] == "matrix_free"
    assert np.abs(a.x - b.x).max() <= 1e-10 * np.abs(a.x).max()


@pytest.mark.parametrize("scene", [crack2d, penny], ids=["2d", "3d"])
def test_pdas_coulomb_fixed_point_agrees_with_the_monolithic_newton(scene):
    qp = with_friction(scene(), "coulomb", 0.15)
    a, b = solve(qp), solve(qp, coulomb="fixed_point")
    assert b.status == "solved" and b.iterations["coulomb_iterations"] > 1
    assert np.abs(a.x - b.x).max() <= 1e-9 * np.abs(a.x).max()


def test_dual_gradient_takes_tresca_not_coulomb():
    from dualfem.core.solver import unhandled_law

    qp = with_friction(crack2d(), "tresca", mixed_bound(crack2d(), 0.1, 0.6))
    a, b = solve(qp), solve(qp, "dual_gradient")
    assert b.status == "solved" and kkt(qp, b) < 1e-9
    assert np.abs(a.x - b.x).max() <= 1e-8 * np.abs(a.x).max()
    assert "does not handle the 'coulomb' law" in unhandled_law(make_solver("dual_gradient"),
                                                                 with_friction(crack2d(), "coulomb", 0.1))


def test_the_runner_certifies_the_frictional_answer():
    from dualfem.experiments.runner import run

    qp = with_friction(crack2d(), "tresca", mixed_bound(crack2d(), 0.1, 0.6))
    sol = run("pdas", qp)
    assert sol.verdict.status == "solved" and sol.verdict.cert_x < 1e-9


@pytest.mark.parametrize("name, params", [("pdas", {"max_iter": 1}), ("mprgp", {"coulomb_max_iter": 1}),
                                          ("mprgp", {"max_iter": 3})])
def test_an_unfinished_friction_solve_is_never_solved(name, params):
    qp = with_friction(penny(), "coulomb", 0.15)                   # needs 6 Newton steps / 8 fixed-point solves
    sol = solve(qp, name, **params)
    assert sol.status == "max_iter"
