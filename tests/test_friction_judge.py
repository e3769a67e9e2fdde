"""The judge on frictional QPs: a solver that ignores friction is never called correct; the Tresca duality-gap
bound is >= the true error (2D box, 3D disc); Coulomb is certified as the Tresca problem with the answer's own
threshold mu_f lambda (said in the certificate's notes)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dualfem.core.evaluator import size_energy
from dualfem.core.laws import Tresca
from dualfem.core.solution import Solution, Status
from dualfem.core.solver import Solver
from dualfem.experiments.compare import compare_solvers
from dualfem.experiments.runner import run
from dualfem.numerics.certify import certified_error
from dualfem.scene import load_scene

pytest.importorskip("gmsh")
pytest.importorskip("clarabel")

#: a box with one crack under f2 (part open, part closed) and a 3D disc: friction changes the answer
SCENES = {"2d": ("f2", {"N": 16, "friction": "tresca", "friction_bound": 5.0}),
          "3d": ("three_d", {"N": 6, "friction": "tresca", "friction_bound": 0.05})}


@pytest.fixture(scope="module", params=["2d", "3d"])
def tresca(request):
    name, keys = SCENES[request.param]
    qp = load_scene(name, keys).build()
    return qp, run("clarabel", qp)


def _frictionless(qp, forces):
    """An answer that ignores friction: the frictionless solution, with friction forces 0 or the ones that
    would oppose its slip (``forces``)."""
    free = run("pdas", dataclasses.replace(qp, blocks=(), store=None))
    b = qp.blocks[0]
    mu_t = np.zeros(b.m) if forces == "zero" else b.law.complementary(np.zeros(b.m), b.G @ free.x, b.weights)
    return free.x, np.concatenate([free.multipliers, mu_t])


@pytest.mark.parametrize("forces", ["zero", "opposing"])
def test_a_solver_ignoring_friction_is_never_correct(tresca, forces, register):
    qp, good = tresca
    x, mu = _frictionless(qp, forces)

    @register
    class IgnoresFriction(Solver):
        name = "hostile_frictionless"
        accepts = ("signorini", "tresca")
        defaults = {"tol": 1e-8}

        def solve(self):
            return Solution(solver=self.name, status=Status.SOLVED, x=x.copy(), multipliers=mu.copy())

    sol = run("hostile_frictionless", qp)
    assert sol.claim == "solved" and sol.status == Status.INACCURATE, sol.message
    out = compare_solvers(qp, ["hostile_frictionless", "clarabel"])
    grades = {r["solver"]: r["grade"] for r in out.rows}
    assert grades["clarabel"] == "correct" and grades["hostile_frictionless"] != "correct", grades


def test_tresca_bound_is_at_least_the_true_error(tresca):
    qp, good = tresca
    assert good.status == Status.SOLVED and good.info["certificate"]["value"] < 1e-9
    rng = np.random.default_rng(1)
    xs, mus = good.x, good.multipliers
    for scale in (1e-6, 1e-4, 1e-2):
        x = xs + scale * np.abs(xs).max() * rng.standard_normal(qp.n)
        x = x + qp.B.T @ (np.maximum(-(qp.B @ x), 0.0) / (qp.B @ qp.B.T).diagonal())    # feasible: B x >= 0
        assert (qp.B @ x).min() >= -1e-15 * np.abs(x).max()
        mu = mus + scale * np.abs(mus).max() * rng.standard_normal(mus.size)
        cert = certified_error(qp, x, mu)
        dx = x - xs
        true = float(np.sqrt(dx @ (qp.K @ dx))) / size_energy(qp, x)
        assert np.isfinite(cert["bound"]) and cert["bound"] >= true * (1 - 1e-9), (scale, cert, true)
        assert cert["bound"] < 1e4 * true          # and not vacuous


def _coulomb_fixed_point(coef, steps=60):
    """A Coulomb answer by the fixed point g <- mu_f lambda over Tresca problems solved by clarabel (the test's
    own, independent of dualfem.numerics.coulomb)."""
    qp = load_scene("f2", {"N": 16, "friction": "coulomb", "friction_coefficient": coef}).build()
    b = qp.blocks[0]
    lam = run("pdas", dataclasses.replace(qp, blocks=(), store=None)).multipliers
    for _ in range(steps):
        g = coef * np.maximum(lam, 0.0) / b.weights          # threshold (stress) whose radius g w = mu_f lambda
        tq = dataclasses.replace(qp, blocks=(dataclasses.replace(b, law=Tresca(g)),), store=None)
        sol = run("clarabel", tq)
        new = sol.multipliers[:qp.m]
        if np.abs(new - lam).max() <= 1e-13 * np.abs(new).max():
            lam = new
            break
        lam = new
    return qp, sol


def test_coulomb_is_certified_as_the_tresca_problem_of_its_own_threshold(register):
    qp, sol = _coulomb_fixed_point(0.5)
    x, mu = sol.x, sol.multipliers

    @register
    class Answer(Solver):
        name = "coulomb_answer"
        accepts = ("signorini", "coulomb")
        defaults = {"tol": 1e-8}

        def solve(self):
            return Solution(solver=self.name, status=Status.SOLVED, x=x.copy(), multipliers=mu.copy())

    good = run("coulomb_answer", qp)
    assert good.status == Status.SOLVED, good.message
    assert "Tresca problem whose threshold is the answer's own" in good.info["certificate"]["notes"]
    fx, fmu = _frictionless(qp, "zero")
    x, mu = fx, fmu
    assert run("coulomb_answer", qp).status == Status.INACCURATE
