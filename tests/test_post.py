"""Post-processing: strains/stresses against closed-form fields, defect fields, transfer, norms."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene
from dualfem.post.fields import (
    Post,
    contact_length,
    defect_fields,
    free_vector,
    mass_norm2,
    nodal_displacement,
    prolongate,
    strains,
    stresses,
    von_mises,
)
from dualfem.problems.thin_defect import lame


@pytest.fixture(scope="module")
def qp8():
    return load_scene("f2", {"N": 8, "delta": 1e-3}).build()


def _field(qp, fn):
    """Free vector of the nodal field fn(X) -> (nnodes, 2) (zero on the clamped bottom if fn is)."""
    return free_vector(qp, fn(np.asarray(qp.geometry.nodes)))


def test_nodal_roundtrip(qp8):
    x = np.random.default_rng(1).standard_normal(qp8.n)
    u = nodal_displacement(qp8, x)
    assert u.shape == (qp8.geometry.nodes.shape[1], 2)
    assert np.array_equal(free_vector(qp8, u), x)
    bottom = np.isclose(qp8.geometry.nodes[1], 0.0)
    assert bottom.any() and np.all(u[bottom] == 0.0)


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_linear_field_stress(plane):
    qp = load_scene("f1", {"N": 8, "plane": plane}).build()
    a, b = 2e-4, -3e-4
    x = _field(qp, lambda X: np.stack([a * X[1], b * X[1]], axis=1))  # u = (a y, b y): zero on y = 0
    eps = strains(qp, x)
    assert np.allclose(eps, [0.0, b, a / 2], atol=1e-15)
    E, nu = 69000.0, 0.3
    st = stresses(qp, x)
    # independent constitutive laws
    if plane == "strain":
        c = E / ((1 + nu) * (1 - 2 * nu))
        s11, s22, s33 = c * nu * b, c * (1 - nu) * b, c * nu * b
    else:
        c = E / (1 - nu ** 2)
        s11, s22, s33 = c * nu * b, c * b, 0.0
    s12 = E / (2 * (1 + nu)) * a
    for k, v in (("s11", s11), ("s22", s22), ("s12", s12), ("s33", s33)):
        assert np.allclose(st[k], v, rtol=1e-12, atol=1e-12), k
    # von Mises = sqrt(3 J2) of the 3x3 stress tensor
    S = np.array([[s11, s12, 0], [s12, s22, 0], [0, 0, s33]])
    dev = S - np.trace(S) / 3 * np.eye(3)
    assert np.allclose(st["von_mises"], np.sqrt(1.5 * np.sum(dev * dev)), rtol=1e-12)
    lam, mu = lame(E, nu, plane)
    assert np.isclose(lam * b + 2 * mu * b, s22)


def test_von_mises_uniaxial():
    assert np.isclose(von_mises(5.0, 0.0, 0.0, 0.0), 5.0)
    assert np.isclose(von_mises(0.0, 0.0, 2.0, 0.0), 2.0 * np.sqrt(3))
    assert np.isclose(von_mises(7.0, 7.0, 0.0, 7.0), 0.0)  # hydrostatic


def test_defect_fields_opening(qp8):
    m = qp8.maps
    X = qp8.geometry.nodes
    U = np.stack([1e-3 * X[1], 2e-3 * X[1]], axis=1)
    U[m["defect_upper"], 1] += 5e-4        # open the faces by 5e-4 in the normal direction
    U[m["defect_upper"], 0] += -1e-4       # and slide them by -1e-4
    x = free_vector(qp8, U)
    mu = np.linspace(1.0, 2.0, qp8.m)
    d = defect_fields(qp8, x, mu)
    k = qp8.m + 2
    assert d["s"].shape == (k,) and d["s"][0] == 0.0 and np.isclose(d["s"][-1], 0.5)
    assert np.all(np.diff(d["s"]) > 0)
    assert d["jump_normal"][0] == 0.0 and d["jump_normal"][-1] == 0.0
    assert np.allclose(d["jump_normal"][1:-1], 5e-4)
    assert np.allclose(d["jump_tangent"][1:-1], -1e-4)
    assert np.allclose(d["jump_normal"][1:-1], qp8.B @ x)
    assert np.isnan(d["pressure"][0]) and np.isnan(d["pressure"][-1])
    assert np.allclose(d["pressure"][1:-1], mu / qp8.weights)
    assert np.allclose(d["force"][1:-1], mu)
    assert np.allclose(d["X"][1], 0.5) and np.allclose(d["X"][0], 0.25 + d["s"])


def test_post_is_lazy_and_needs_material(qp8):
    x = np.zeros(qp8.n)
    p = Post(qp8, x=x, multipliers=np.zeros(qp8.m))
    assert "stress" not in p.__dict__ and "defect" not in p.__dict__
    assert p.von_mises.shape == (qp8.geometry.cells.shape[1],)
    assert "stress" in p.__dict__ and "defect" not in p.__dict__
    bare = type(qp8)(K=qp8.K, F=qp8.F, B=qp8.B, weights=qp8.weights, maps=qp8.maps)
    with pytest.raises(InputError, match="E and nu"):
        _ = Post(bare, x=x).stress
    assert Post(bare, x=x, E=1.0, nu=0.25).von_mises.max() == 0.0
    nomaps = type(qp8)(K=qp8.K, F=qp8.F, B=qp8.B)
    with pytest.raises(InputError, match="mesh of the QP"):
        Post(nomaps, x=x)


def test_deformed(qp8):
    x = np.random.default_rng(2).standard_normal(qp8.n) * 1e-4
    p = Post(qp8, x=x)
    assert np.allclose(p.deformed(300.0), qp8.geometry.nodes + 300.0 * nodal_displacement(qp8, x).T)


def test_contact_length():
    s = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    jump = np.array([0.0, 0.0, 0.0, 1e-3, 2e-3, 0.0])
    assert np.isclose(contact_length(s, jump, 1e-9), 0.2)
    assert contact_length(s, np.full(6, 1.0), 1e-9) == 0.0
    assert np.isclose(contact_length(s, np.zeros(6), 1e-9), 0.5)


def test_prolongate_reproduces_coarse_p1(qp8):
    fine = load_scene("f2", {"N": 32, "delta": 1e-3}).build()
    xc = np.random.default_rng(3).standard_normal(qp8.n)
    xf = prolongate(qp8, xc, fine)
    Uc, Uf = nodal_displacement(qp8, xc), nodal_displacement(fine, xf)
    # every fine node that coincides with a single coarse node carries its value
    Pc, Pf = np.round(qp8.geometry.nodes.T, 9), np.round(fine.geometry.nodes.T, 9)
    index = {}
    for i, p in enumerate(map(tuple, Pc)):
        index.setdefault(p, []).append(i)
    n_checked = 0
    for j, p in enumerate(map(tuple, Pf)):
        if len(index.get(p, [])) == 1:
            assert np.allclose(Uf[j], Uc[index[p][0]])
            n_checked += 1
    assert n_checked == 9 * 9 - 3  # every coarse position except the 3 doubled defect nodes
    # doubled defect nodes: upper copies from the upper side, lower from the lower side
    for side in ("defect_upper", "defect_lower"):
        assert np.allclose(Uf[fine.maps[side][3::4]], Uc[qp8.maps[side]])
    # nested P1 spaces: the transferred field is the same function, so its L2 norm and its
    # elastic energy computed on the fine mesh equal those computed on the coarse mesh
    assert np.isclose(mass_norm2(fine, xf), mass_norm2(qp8, xc), rtol=1e-10)
    assert np.isclose(xf @ (fine.K_fixed @ xf), xc @ (qp8.K_fixed @ xc), rtol=1e-10)
    # (not the interface term: the trapezoid rule for int |[v]|^2 depends on the mesh)


def test_mass_norm_matches_skfem(qp8):
    from skfem import BilinearForm, asm
    from skfem.helpers import dot

    prob = load_scene("f2", {"N": 8, "delta": 1e-3})
    qp = prob.build()
    basis = prob.basis()

    @BilinearForm
    def mass(u, v, w):
        return dot(u, v)

    M = asm(mass, basis)
    x = np.random.default_rng(4).standard_normal(qp.n)
    nd = qp.geometry.node_dofs
    full = np.zeros(basis.N)
    mask = nd >= 0
    full[basis.nodal_dofs[mask]] = x[nd[mask]]
    assert np.isclose(mass_norm2(qp, x), full @ (M @ full), rtol=1e-12)


def test_transfer_errors_decrease():
    """Coarse exact solutions approach a finer one (energy-norm and L2 errors shrink with h)."""
    from dualfem.experiments.convergence import errors
    from dualfem.experiments.runner import run
    from dualfem.post.figures import pick_solver

    solver = pick_solver()
    fine = load_scene("f2", {"N": 32, "delta": 1e-1}).build()
    sf = run(solver, fine)
    errs = []
    for N in (8, 16):
        qc = load_scene("f2", {"N": N, "delta": 1e-1}).build()
        sc = run(solver, qc)
        errs.append(errors(fine, sf.x, qc, sc.x))
    assert errs[1]["energy_norm"] < 0.8 * errs[0]["energy_norm"]
    assert errs[1]["L2"] < 0.6 * errs[0]["L2"]
    same = errors(fine, sf.x, fine, sf.x)
    assert same["energy_norm"] < 1e-12 and same["L2"] < 1e-12


def test_nodal_displacement_applies_x_shift():
    from dualfem.core.scene import load_scene
    from dualfem.post.fields import nodal_displacement

    problem = load_scene("signorini", {})
    qp = problem.build()
    x = np.zeros(qp.n)
    u = nodal_displacement(qp, x)
    nd = np.asarray(qp.geometry.node_dofs)
    shift = np.asarray(qp.shift.x)
    assert np.abs(shift).max() > 0
    mask = nd >= 0
    assert np.allclose(u.T[mask], shift[nd[mask]])


def test_free_vector_inverts_nodal_displacement_with_shift():
    from dualfem.core.scene import load_scene
    from dualfem.post.fields import free_vector, nodal_displacement

    qp = load_scene("signorini", {}).build()
    x = np.random.default_rng(0).normal(size=qp.n)
    assert np.allclose(free_vector(qp, nodal_displacement(qp, x)), x)
