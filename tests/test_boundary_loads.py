"""General supports and loads (problems/_boundary.py) in 2D and 3D, and their wiring into the 2D scenes:
uniform states carried exactly, zero reactions of the rigid-body removal, consistent loads, face pressure
by superposition, rotation invariance, legacy scenes unchanged, bad keys refused."""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from dualfem.core.errors import InputError
from dualfem.problems import _boundary as bd


# --------------------------------------------------------------------------- helpers
def _mesh(dim: int, n: int, box):
    from skfem import MeshTet, MeshTri

    axes = [np.linspace(0, L, n + 1) for L in box]
    m = (MeshTri if dim == 2 else MeshTet).init_tensor(*axes)
    return m.p, m.t


def _stiffness(p, t, E=1000.0, nu=0.3):
    """K on all dofs (dof dim i + c: component c of node i), scikit-fem's own assembly (an independent one)."""
    from skfem import Basis, ElementTetP1, ElementTriP1, ElementVector, MeshTet, MeshTri, asm
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    dim = p.shape[0]
    mesh = (MeshTri if dim == 2 else MeshTet)(p, t)
    basis = Basis(mesh, ElementVector(ElementTriP1() if dim == 2 else ElementTetP1()))
    assert np.array_equal(basis.nodal_dofs, np.arange(dim * p.shape[1]).reshape(-1, dim).T)
    lam, mu = lame_parameters(E, nu)
    return asm(linear_elasticity(lam, mu), basis).tocsc(), lam, mu


def _solve(K, F, mask):
    """u (dim, n) with the masked components zero; the reactions K u - F (dim, n)."""
    dim, n = F.shape
    free = ~mask.T.ravel()
    f = F.T.ravel()
    u = np.zeros(dim * n)
    u[free] = spla.spsolve(K[free][:, free].tocsc(), f[free])
    return u.reshape(n, dim).T, (K @ u - f).reshape(n, dim).T


def _strains(p, t, u):
    """Constant strain (dim, dim, nc) of P1 displacements u (dim, n)."""
    V = p[:, t]                                           # (dim, dim+1, nc)
    D = np.einsum("dkc->cdk", V[:, 1:] - V[:, :1])         # columns: edge vectors
    U = np.einsum("dkc->cdk", u[:, t][:, 1:] - u[:, t][:, :1])
    G = U @ np.linalg.inv(D)                               # grad u (nc, dim, dim)
    return np.einsum("cij->ijc", 0.5 * (G + G.transpose(0, 2, 1)))


def _stress(eps, lam, mu):
    dim = eps.shape[0]
    tr = np.trace(eps)
    return lam * tr[None, None] * np.eye(dim)[:, :, None] + 2 * mu * eps


def _params(dim, **kw):
    base = {"width": 2.0, "height": 1.0} if dim == 2 else {"width": 2.0, "depth": 1.5, "height": 1.0}
    return {**base, **kw}


# --------------------------------------------------------------------------- the module
def test_no_keys_is_legacy():
    assert bd.parse_loads(_params(2), 2) is None
    assert bd.parse_loads(_params(2, boundary=(), body_force=None, remote_stress=None), 2) is None


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("stress", ["tension", "shear", "hydrostatic"])
def test_uniform_stress_without_supports(dim, stress):
    """No support: only the rigid motions are removed (3 / 6 components); the body carries exactly the
    remote stress in every element and the reactions vanish."""
    S = {"tension": np.diag([3.0, -1.0, 2.0][:dim]),
         "shear": np.array([[0.0, 2.0, 0.5], [2.0, 0.0, -1.0], [0.5, -1.0, 0.0]])[:dim, :dim],
         "hydrostatic": -4.0 * np.eye(dim)}[stress]
    params = _params(dim, remote_stress=S.tolist())
    spec = bd.parse_loads(params, dim)
    p, t = _mesh(dim, 4 if dim == 2 else 2, spec.box)
    sides = bd.box_sides(p, t, spec.box)
    mask = bd.fixed_mask(spec, p, sides)
    assert mask.sum() == (3 if dim == 2 else 6)
    F = bd.nodal_forces(spec, p, t, sides)
    bd.check_balance(spec, p, sides, F)
    K, lam, mu = _stiffness(p, t)
    u, react = _solve(K, F, mask)
    sig = _stress(_strains(p, t, u), lam, mu)
    assert np.abs(sig - S[:, :, None]).max() <= 1e-10 * np.abs(S).max()
    assert np.abs(react).max() <= 1e-10 * np.abs(F).max()


@pytest.mark.parametrize("dim", [2, 3])
def test_side_tractions_equal_remote_stress(dim):
    """[[boundary]] tractions sigma.n on every side give the very same nodal forces as remote_stress."""
    S = np.array([[1.0, 0.5, 0.2], [0.5, -2.0, 0.3], [0.2, 0.3, 0.7]])[:dim, :dim]
    a = bd.parse_loads(_params(dim, remote_stress=S.tolist()), dim)
    tabs = [{"side": s, "traction": (S @ bd.outward_normal(s, dim)).tolist()} for s in bd.SIDES[dim]]
    b = bd.parse_loads(_params(dim, boundary=tabs), dim)
    p, t = _mesh(dim, 3, a.box)
    sides = bd.box_sides(p, t, a.box)
    assert np.allclose(bd.nodal_forces(a, p, t, sides), bd.nodal_forces(b, p, t, sides), rtol=0, atol=1e-14)
    assert np.array_equal(bd.fixed_mask(a, p, sides), bd.fixed_mask(b, p, sides))


def test_box_sides_counts():
    p, t = _mesh(2, 4, (2.0, 1.0))
    s = bd.box_sides(p, t, (2.0, 1.0))
    assert {k: v.shape for k, v in s.items()} == {k: (2, 4) for k in bd.SIDES[2]}
    assert np.all(np.abs(p[1, s["top"]] - 1.0) < 1e-15) and np.all(p[0, s["left"]] == 0)
    p, t = _mesh(3, 2, (2.0, 1.5, 1.0))
    s = bd.box_sides(p, t, (2.0, 1.5, 1.0))
    assert {k: v.shape for k, v in s.items()} == {k: (3, 8) for k in bd.SIDES[3]}
    assert np.all(p[1, s["back"]] == 1.5) and np.all(p[2, s["bottom"]] == 0)


@pytest.mark.parametrize("k", [1, 2, 3])
def test_simplex_rule_exact(k):
    """Monomials x^a y^b z^c on the unit simplex: exact integral a! b! c! / (a + b + c + k)! (k! x mean)."""
    lam, w = bd.simplex_rule(k)
    assert np.isclose(w.sum(), 1.0) and np.all(w > 0)
    deg = {1: 7, 2: 6, 3: 3}[k]
    for e in np.ndindex(*(deg + 1,) * k):
        if sum(e) > deg:
            continue
        exact = math.prod(math.factorial(a) for a in e) / math.factorial(sum(e) + k) * math.factorial(k)
        val = w @ np.prod([lam[:, 1 + i] ** a for i, a in enumerate(e)], axis=0)
        assert abs(val - exact) <= 1e-14, (e, val, exact)


def test_expression_traction_consistent():
    """A linear traction 'x' on the top side: total force = its integral, first moment = its integral."""
    spec = bd.parse_loads(_params(2, boundary=[{"side": "top", "traction": [0, "3*x - 1"]},
                                               {"side": "bottom", "support": "clamp"}]), 2)
    p, t = _mesh(2, 5, spec.box)
    F = bd.nodal_forces(spec, p, t, bd.box_sides(p, t, spec.box))
    W = 2.0                                              # int_0^W (3x - 1) dx, int_0^W x (3x - 1) dx
    assert np.isclose(F[1].sum(), 1.5 * W ** 2 - W, rtol=1e-14) and np.isclose(F[0].sum(), 0)
    assert np.isclose(F[1] @ p[0], W ** 3 - W ** 2 / 2, rtol=1e-13)


def test_roller_and_traction_uniaxial():
    """Roller on the bottom (and one x component fixed), pull on the top: uniaxial stress sigma_yy = t."""
    spec = bd.parse_loads(_params(2, boundary=[{"side": "bottom", "support": "roller"},
                                               {"side": "top", "traction": [0, 5.0]}]), 2)
    p, t = _mesh(2, 4, spec.box)
    sides = bd.box_sides(p, t, spec.box)
    mask = bd.fixed_mask(spec, p, sides)
    assert mask[1].sum() == 5 and mask[0].sum() == 1     # 5 bottom nodes in y, one x to stop sliding
    K, lam, mu = _stiffness(p, t)
    u, react = _solve(K, bd.nodal_forces(spec, p, t, sides), mask)
    sig = _stress(_strains(p, t, u), lam, mu)
    assert np.abs(sig - np.diag([0.0, 5.0])[:, :, None]).max() <= 1e-10 * 5
    assert abs(react[0]).max() <= 1e-10 * 5


def test_body_force_reaction():
    """Gravity on a bar clamped at its bottom: the total reaction equals the total body force exactly."""
    spec = bd.parse_loads(_params(2, boundary=[{"side": "bottom", "support": "clamp"}],
                                  body_force=[0.0, "-2*(1 + y)"]), 2)
    p, t = _mesh(2, 4, spec.box)
    sides = bd.box_sides(p, t, spec.box)
    F = bd.nodal_forces(spec, p, t, sides)
    assert np.isclose(F[1].sum(), -2 * (1 + 0.5) * 2.0, rtol=1e-14)      # int (1 + y) over (0, 2) x (0, 1)
    K, _, _ = _stiffness(p, t)
    u, react = _solve(K, F, bd.fixed_mask(spec, p, sides))
    assert np.isclose(react[1].sum(), -F[1].sum(), rtol=1e-12) and u[1].min() < 0


def test_unbalanced_load_without_support_refused():
    spec = bd.parse_loads(_params(2, body_force=[0.0, -1.0]), 2)
    p, t = _mesh(2, 3, spec.box)
    sides = bd.box_sides(p, t, spec.box)
    with pytest.raises(InputError, match="equilibrium"):
        bd.check_balance(spec, p, sides, bd.nodal_forces(spec, p, t, sides))


@pytest.mark.parametrize("deg", [0.0, 30.0, 90.0])
def test_rigid_removal_well_conditioned(deg):
    """The 3 / 6 chosen components remove exactly the rigid motions (checked on rotated bodies too)."""
    for dim in (2, 3):
        spec = bd.parse_loads(_params(dim, remote_stress=np.eye(dim).tolist()), dim)
        p, t = _mesh(dim, 2, spec.box)
        c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        Rm = np.array([[c, -s], [s, c]]) if dim == 2 else np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        mask = bd.fixed_mask(spec, Rm @ p, bd.box_sides(p, t, spec.box))
        comp, idx = np.nonzero(mask)
        centre, length = bd._frame(Rm @ p)
        M = bd._modes((Rm @ p)[:, idx], comp, centre, length)
        assert M.shape == ((3, 3) if dim == 2 else (6, 6))
        assert bd._condition(M) >= bd.MIN_CONDITION


def test_face_pressure_forces():
    nu = np.array([[0.0, 0.6], [1.0, 0.8]])
    F = bd.face_pressure_forces(np.array([5, 6]), np.array([1, 2]), nu, np.array([0.5, 0.25]),
                                np.array([2.0, 4.0]), 7)
    assert np.allclose(F[:, 5], [0, 1.0]) and np.allclose(F[:, 1], [0, -1.0])
    assert np.allclose(F[:, 6], [0.6, 0.8]) and np.allclose(F.sum(axis=1), 0)


BAD = [
    ({"boundary": [{"side": "middle", "support": "clamp"}]}, 2, r"boundary\[0\]\.side.*left, right, bottom, top"),
    ({"boundary": [{"side": "front", "support": "clamp"}]}, 2, r"boundary\[0\]\.side.*3D"),
    ({"boundary": [{"side": "top", "support": "clamp"}, {"side": "top", "support": "free"}]}, 2,
     r"boundary\[1\]\.side.*twice"),
    ({"boundary": [{"side": "top", "support": "glue"}]}, 2, r"boundary\[0\]\.support.*clamp, roller, free"),
    ({"boundary": [{"side": "top"}]}, 2, r"boundary\[0\].*support"),
    ({"boundary": [{"side": "top", "traction": [1, 2, 3]}]}, 2, r"boundary\[0\]\.traction.*2 numbers"),
    ({"boundary": [{"side": "top", "traction": [0, "log(x - 1)"]}]}, 2, r"boundary\[0\]\.traction\[1\].*top"),
    ({"boundary": [{"side": "left", "traction": [0, "1/x"]}]}, 2, r"boundary\[0\]\.traction\[1\].*NaN or inf"),
    ({"boundary": [{"side": "top", "traction": [0, "foo(x)"]}]}, 2, r"boundary\[0\]\.traction\[1\]"),
    ({"boundary": [{"side": "top", "support": "clamp", "traction": [0, 1]}]}, 2, r"boundary\[0\].*clamp"),
    ({"boundary": [{"side": "top", "load": 1}]}, 2, r"boundary\[0\].*unknown key 'load'"),
    ({"remote_stress": [[1, 2], [3, 4]]}, 2, r"remote_stress.*symmetric"),
    ({"remote_stress": [[1, 0], [0, float("nan")]]}, 2, r"remote_stress"),
    ({"remote_stress": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}, 2, r"remote_stress.*2x2"),
    ({"remote_stress": [[1, 0], [0, 1]], "boundary": [{"side": "top", "traction": [0, 1]}]}, 2,
     r"boundary\[0\]\.traction.*remote_stress"),
    ({"body_force": [0, 0, -1]}, 2, r"body_force.*2 numbers"),
    ({"body_force": [0, True]}, 2, r"body_force\[1\]"),
    ({"body_force": [0, "z"]}, 2, r"body_force\[1\]"),
    ({"body_force": [0, "-1", "z*x"], "boundary": [{"side": "front", "support": "clamp"}]}, 3, None),
]


@pytest.mark.parametrize("keys, dim, needle", BAD)
def test_bad_keys_refused(keys, dim, needle):
    if needle is None:                                     # z is a variable in 3D
        assert bd.parse_loads(_params(dim, **keys), dim) is not None
        return
    with pytest.raises(InputError, match=needle):
        bd.parse_loads(_params(dim, **keys), dim)
