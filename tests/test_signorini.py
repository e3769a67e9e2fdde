"""Signorini contact with a rigid foundation (problems/signorini.py): exact solvers agree, and
the physics is checkable: exact uniform pressure on a flat foundation, global equilibrium."""
import numpy as np
import pytest

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.registry import solvers
from dualfem.core.scene import load_scene
from dualfem.core.solution import Status
from dualfem.experiments.runner import run


def exact_solvers():
    """Exact solvers registered and installed now (whatever the other plugins are)."""
    reg = solvers()
    return [n for n, c in sorted(reg.items()) if c.exact and c.missing() is None]


def reference_name():
    reg = solvers()
    for n in ("pdas", "clarabel"):
        if n in reg and reg[n].missing() is None:
            return n
    pytest.skip("no exact reference solver (pdas, clarabel) installed")


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_flat_foundation_uniform_pressure_is_exact(plane):
    pr = load_scene("signorini_flat", {"N": 8, "plane": plane, "E": 1000.0, "nu": 0.25, "indent": 0.01})
    qp = pr.build()
    sol = run(reference_name(), qp)
    assert sol.status == Status.SOLVED
    expected = (1000.0 / (1 - 0.25 ** 2) if plane == "strain" else 1000.0) * 0.01 / 0.5
    assert pr.flat_pressure() == pytest.approx(expected, rel=1e-14)
    # P1 reproduces the homogeneous uniaxial state exactly: pressure at every bottom node
    np.testing.assert_allclose(qp.pressure(sol.multipliers), expected, rtol=1e-7)
    assert evaluator.contact_set(qp, sol.x).all()
    # in the punch's frame u2 varies linearly from indent (bottom) to 0 (top)
    nodes, nd = qp.geometry.nodes, qp.geometry.node_dofs
    u = pr.displacement(sol.x)
    has = nd[1] >= 0
    np.testing.assert_allclose(u[nd[1, has]], 0.01 * (1 - nodes[1, has] / 0.5), atol=1e-9 * 0.01)
    # lateral expansion: eps11 = -nu/(1-nu) eps22 (plane strain) or -nu eps22 (plane stress)
    nu_eff = 0.25 / (1 - 0.25) if plane == "strain" else 0.25
    has1 = nd[0] >= 0
    slope = np.polyfit(nodes[0, has1], u[nd[0, has1]], 1)[0]
    assert slope == pytest.approx(nu_eff * 0.01 / 0.5, rel=1e-7)


def test_curved_obstacle_equilibrium_and_partial_contact():
    pr = load_scene("signorini", {"N": 16})
    qp = pr.build()
    sol = run(reference_name(), qp)
    assert sol.status == Status.SOLVED
    assert evaluator.kkt_error(sol.residuals) < 1e-8
    mu = sol.multipliers
    vertical, horizontal = pr.punch_force(sol.x)
    # total contact force = total force applied by the punch (from K rows the QP does not hold)
    assert mu.sum() > 0
    assert mu.sum() == pytest.approx(-vertical, rel=1e-8)
    assert abs(horizontal) < 1e-8 * mu.sum()        # frictionless: no horizontal reaction
    c = evaluator.contact_set(qp, sol.x)
    assert 0 < c.sum() < qp.m                        # partial contact
    assert c[qp.m // 2] and not c[0] and not c[-1]   # in contact under the bump's top only
    # in contact <=> the bottom node lies on the foundation surface x2 = indent - g(x) (punch frame)
    u2_bottom = pr.displacement(sol.x)[qp.geometry.node_dofs[1, qp.maps["contact_nodes"]]]
    np.testing.assert_allclose((u2_bottom + qp.maps["gap"] - 0.005)[c], 0.0, atol=1e-9 * 0.005)
    assert np.all((u2_bottom + qp.maps["gap"] - 0.005)[~c] > 0)
    assert np.all(mu[~c] <= 1e-8 * mu.max())
    # the QP energy plus the stored offset is the potential energy of the displacement
    K, F = qp.K, qp.F + qp.K @ qp.shift.x
    u = pr.displacement(sol.x)
    assert qp.energy(sol.x) + float(qp.shift.objective) == pytest.approx(0.5 * u @ (K @ u) - F @ u, rel=1e-10)


def test_exact_solvers_agree():
    qp = load_scene("signorini", {"N": 12}).build()
    ref = run(reference_name(), qp)
    names = exact_solvers()
    assert "dual_gradient" in names and len(names) >= 2
    for name in names:
        s = run(name, qp)
        if s.status == Status.SKIPPED or (s.status != Status.SOLVED and solvers()[name].requires):
            continue          # a third-party library may fail honestly (its certified status says so)
        assert s.status == Status.SOLVED, (name, s.message)
        d = evaluator.compare(qp, s.x, s.multipliers, ref.x, ref.multipliers)
        tol = max(solvers()[name].tolerance, 1e-6)
        assert d["x_energy"] < tol, (name, d)
        assert d["multipliers"] < 10 * tol, (name, d)
        assert d["contact_mismatch"] == 0, (name, d)


def test_more_indentation_more_force_and_contact():
    forces, contacts = [], []
    for d in (0.002, 0.005, 0.01):
        qp = load_scene("signorini", {"N": 16, "indent": d}).build()
        s = run(reference_name(), qp)
        forces.append(s.multipliers.sum())
        contacts.append(evaluator.contact_set(qp, s.x).sum())
    assert forces[0] < forces[1] < forces[2]
    assert contacts[0] <= contacts[1] <= contacts[2] and contacts[0] < contacts[2]


@pytest.mark.parametrize("key,value,needle", [
    ("obstacle", "-1", "negative initial gap"),
    ("obstacle", "import_os", "not allowed"),
    ("obstacle", "x.real", "only arithmetic"),
    ("obstacle", "1/(x-x)", "NaN or infinite"),
    ("indent", "-0.1", "indent"),
    ("N", "1", "N"),
    ("plane", "3d", "plane"),
])
def test_bad_input(key, value, needle):
    with pytest.raises(InputError, match=needle):
        load_scene("signorini", {key: value})


def test_cli_solve_signorini(capsys):
    from dualfem.cli.main import main

    rc = main(["solve", "signorini", "--set", "N=8", "--solver", "dual_gradient", "--json"])
    assert rc == 0
    import json

    rec = json.loads(capsys.readouterr().out)
    assert rec["status"] == "solved" and rec["problem"] == "signorini[obstacle]"
    assert 0 < rec["n_contact"] < rec["n_defect_nodes"]
