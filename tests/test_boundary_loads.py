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


def test_body_force_3d_total():
    """A body force expression on tetrahedra: its resultant and first moment are the exact integrals."""
    spec = bd.parse_loads(_params(3, boundary=[{"side": "bottom", "support": "clamp"}],
                                  body_force=["z", 0.0, "-1 - x*y"]), 3)
    p, t = _mesh(3, 2, spec.box)
    F = bd.nodal_forces(spec, p, t, bd.box_sides(p, t, spec.box))
    W, D, H = spec.box
    assert np.isclose(F[0].sum(), W * D * H ** 2 / 2, rtol=1e-13) and F[1].sum() == 0
    assert np.isclose(F[2].sum(), -W * D * H - W ** 2 * D ** 2 * H / 4, rtol=1e-13)
    assert np.isclose(F[0] @ p[2], W * D * H ** 3 / 3, rtol=1e-13)          # int z * z dV (P1 interpolates z)


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


# --------------------------------------------------------------------------- the 2D scenes
def _scene(spec="f2", **kw):
    from dualfem.core.scene import load_scene

    return load_scene(spec, {"N": 8, **kw})


def _solve_qp(qp):
    from dualfem.experiments.runner import run

    sol = run("pdas", qp, {})
    assert sol.status == "solved", sol.message
    return sol


def _all_nodes(qp, x):
    """Displacements (2, n) of every node from the QP's unknowns (0 where fixed)."""
    nd = qp.geometry.node_dofs
    u = np.zeros(nd.shape)
    u[nd >= 0] = x[nd[nd >= 0]]
    return u


def _scene_stress(problem, qp, u):
    from dualfem.core.elasticity import lame

    p = problem.params
    lam, mu = lame(p["E"], p["nu"], p["plane"])
    return _stress(_strains(qp.geometry.nodes, qp.geometry.cells, u), lam, mu)


def _glued(problem):
    """The uncracked body: the doubled copies merged back (K_all summed onto the originals), solved with the
    scene's fixed unknowns. Returns (qp, u (2, n) on every node, reactions at the fixed unknowns, F_all)."""
    import scipy.sparse as sp

    K_all, F_all, _ = problem.assemble()
    qp = problem.build()
    c, _ = problem.cut()
    n = qp.geometry.node_dofs.shape[1]
    orig = np.arange(n)
    orig[c.upper] = c.lower
    P = sp.csr_matrix((np.ones(2 * n), (np.arange(2 * n), (2 * orig[:, None] + [0, 1]).ravel())), shape=(2 * n, 2 * n))
    Kg, Fg = (P.T @ K_all @ P).tocsc(), P.T @ F_all
    fixed = (qp.geometry.node_dofs < 0).T.ravel()
    fixed[2 * c.upper] = fixed[2 * c.upper + 1] = True            # the copies are gone
    ug = np.zeros(2 * n)
    ug[~fixed] = spla.spsolve(Kg[~fixed][:, ~fixed].tocsc(), Fg[~fixed])
    react = (Kg @ ug - Fg)[(qp.geometry.node_dofs < 0).T.ravel()]
    return qp, (P @ ug).reshape(n, 2).T, react, F_all


STATES = {"tension": [[3.0, 0.0], [0.0, 2.0]], "shear": [[0.0, 2.0], [2.0, 0.0]],
          "hydrostatic": [[-4.0, 0.0], [0.0, -4.0]], "general": [[1.0, -0.7], [-0.7, -2.5]]}


@pytest.mark.parametrize("rot", [0.0, 30.0])
@pytest.mark.parametrize("state", list(STATES))
def test_scene_uncracked_carries_remote_stress(state, rot):
    """The scene's own assembly, uncracked (copies merged), no support: every element carries R S R' exactly
    (to 1e-10 of |S|), and the reactions at the 3 fixed components vanish."""
    S = np.array(STATES[state])
    problem = _scene(remote_stress=S.tolist(), rotate_deg=rot)
    qp, u, react, F_all = _glued(problem)
    assert (qp.geometry.node_dofs < 0).sum() == 3
    c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
    R = np.array([[c, -s], [s, c]])
    sig = _scene_stress(problem, qp, u)
    assert np.abs(sig - (R @ S @ R.T)[:, :, None]).max() <= 1e-10 * np.abs(S).max()
    assert np.abs(react).max() <= 1e-10 * np.abs(F_all).max()


def test_boundary_tractions_give_the_remote_stress_qp():
    S = np.array(STATES["general"])
    a = _scene(remote_stress=S.tolist()).build()
    tabs = [{"side": s, "traction": (S @ bd.outward_normal(s, 2)).tolist()} for s in bd.SIDES[2]]
    b = _scene(boundary=tabs).build()
    assert np.array_equal(a.geometry.node_dofs, b.geometry.node_dofs)
    assert (a.K != b.K).nnz == 0 and (a.B != b.B).nnz == 0
    assert np.abs(a.F - b.F).max() <= 1e-14 * np.abs(a.F).max()
    xa, xb = _solve_qp(a).x, _solve_qp(b).x
    assert np.abs(xa - xb).max() <= 1e-10 * np.abs(xa).max()


def test_compression_closes_the_crack():
    """Hydrostatic compression p: the crack is closed everywhere, the contact pressure is p, the stress -p I."""
    problem = _scene(remote_stress=[[-4.0, 0.0], [0.0, -4.0]])
    qp = problem.build()
    sol = _solve_qp(qp)
    assert np.abs(qp.B @ sol.x).max() <= 1e-10 * np.abs(sol.x).max()
    assert np.allclose(qp.pressure(sol.multipliers), 4.0, rtol=1e-8)
    sig = _scene_stress(problem, qp, _all_nodes(qp, sol.x))
    assert np.abs(sig + 4.0 * np.eye(2)[:, :, None]).max() <= 1e-8 * 4


@pytest.mark.parametrize("mesh", ["structured", "gmsh"])
def test_face_pressure_is_remote_tension_by_superposition(mesh):
    """A crack under face pressure p in an unloaded body = the crack under remote tension p (normal to it)
    minus the uncracked uniform solution: the same displacements (hence openings) to 1e-8."""
    p = 3.0
    kw = {"mesh": mesh, "mesh_size": 0.1, "tip_size": 0.05} if mesh == "gmsh" else {}
    d = [{"points": [[0.25, 0.5], [0.75, 0.5]], "face_pressure": p}]
    pressed = _scene(defects=d, remote_stress=[[0.0, 0.0], [0.0, 0.0]], **kw)
    remote = _scene(defects=[{"points": d[0]["points"]}], remote_stress=[[0.0, 0.0], [0.0, p]], **kw)
    qa, qb = pressed.build(), remote.build()
    assert np.array_equal(qa.geometry.node_dofs, qb.geometry.node_dofs)
    xa, xb = _solve_qp(qa).x, _solve_qp(qb).x
    assert (qa.B @ xa).min() > 0                                 # the pressure opens the whole crack
    _, u0, _, _ = _glued(remote)
    va, vb = _all_nodes(qa, xa), _all_nodes(qb, xb) - u0
    assert np.abs(va - vb).max() <= 1e-8 * np.abs(va).max()
    assert np.abs(qa.B @ xa - qb.B @ xb).max() <= 1e-8 * np.abs(qa.B @ xa).max()


def test_face_pressure_expression_and_sign():
    """face_pressure as an expression; its resultant is zero (both faces) and the + face is pushed along nu."""
    problem = _scene(defects=[{"points": [[0.25, 0.5], [0.75, 0.5]], "face_pressure": "2 + x"}])
    F = problem.nodal_load()
    c, _ = problem.cut()
    assert np.all(F[1, c.upper] > 0) and np.all(F[1, c.lower] < 0)
    assert np.allclose(F[1, c.upper], (2 + c.points[0, c.lower]) * c.weights)
    legacy = _scene().nodal_load()
    assert np.allclose((F - legacy)[1].sum(), 0) and np.array_equal(np.delete(F, np.r_[c.upper, c.lower], 1),
                                                                   np.delete(legacy, np.r_[c.upper, c.lower], 1))


def test_rotation_leaves_energy_and_contact_unchanged():
    S = [[1.0, -1.5], [-1.5, -2.0]]                 # the crack is partly closed, partly slipping
    qa, qb = _scene(remote_stress=S).build(), _scene(remote_stress=S, rotate_deg=37.0).build()
    sa, sb = _solve_qp(qa), _solve_qp(qb)
    ea, eb = qa.energy(sa.x), qb.energy(sb.x)
    assert abs(ea - eb) <= 1e-9 * abs(ea)
    assert np.array_equal(sa.multipliers > 1e-9 * sa.multipliers.max(), sb.multipliers > 1e-9 * sb.multipliers.max())


def test_body_force_on_clamped_bar():
    """Gravity on a body clamped at its bottom: total reaction = total body force (exactly), sagging."""
    rho_g = 2.5
    problem = _scene(boundary=[{"side": "bottom", "support": "clamp"}], body_force=[0.0, -rho_g],
                     width=0.5, defect=[[0.125, 0.5], [0.375, 0.5]])
    qp = problem.build()
    sol = _solve_qp(qp)
    K_all, F_all, _ = problem.assemble()
    u = _all_nodes(qp, sol.x)
    react = (K_all @ u.T.ravel() - F_all).reshape(-1, 2).T
    fixed = qp.geometry.node_dofs < 0
    assert np.isclose(F_all[1::2].sum(), -rho_g * 0.5 * 1.0, rtol=1e-14)
    assert np.isclose(react[1][fixed[1]].sum(), rho_g * 0.5, rtol=1e-9)
    assert abs(react[0][fixed[0]].sum()) <= 1e-9 * rho_g
    assert u[1].min() < 0 and np.argmin(u[1]) in np.flatnonzero(qp.geometry.nodes[1] == 1.0)


def test_roller_bottom_pull_top_is_uniaxial():
    """Roller on the bottom, pull t on the top, a vertical crack (its faces see no traction): sigma = t e_y e_y'
    in every element, no jump."""
    t = 5.0
    problem = _scene(boundary=[{"side": "bottom", "support": "roller"}, {"side": "top", "traction": [0, t]}],
                     defect=[[0.5, 0.25], [0.5, 0.75]])
    qp = problem.build()
    nd = qp.geometry.node_dofs
    assert (nd[1] < 0).sum() == 9 and (nd[0] < 0).sum() == 1
    sol = _solve_qp(qp)
    sig = _scene_stress(problem, qp, _all_nodes(qp, sol.x))
    assert np.abs(sig - np.diag([0.0, t])[:, :, None]).max() <= 1e-9 * t


LEGACY = ["f1", "f2", "f3"]


@pytest.mark.parametrize("spec", LEGACY + ["library"])
def test_legacy_scenes_keep_their_supports_and_load(spec):
    """Without the new keys: the bottom clamped, the top traction `load` (the legacy path: node_dofs are
    those of the clamp, the name and parameters are unchanged)."""
    import tomllib

    from dualfem.core.scene import library, load_scene
    from dualfem.problems.thin_defect.assemble import free_dofs

    specs = [str(p) for p in library().values() if not set(bd.KEYS) & set(tomllib.loads(p.read_text()))] \
        if spec == "library" else [spec]
    assert len(specs) >= (6 if spec == "library" else 1)
    for s in specs:
        problem = load_scene(s, {"N": 8} if spec != "library" else {})
        qp = problem.build()
        c, _ = problem.cut()
        bottom = np.flatnonzero(np.abs(c.points[1]) <= 1e-9)
        assert np.array_equal(qp.geometry.node_dofs, free_dofs(bottom, c.points.shape[1])), s
        assert "loads" not in qp.params and not any(k in qp.params for k in bd.KEYS), s
        assert qp.name.startswith("thin_defect[") and "loads" not in qp.name, s


def test_legacy_load_as_boundary_tables_same_qp():
    """f1 written with the new keys (bottom clamp, top traction [0, -3]) is the f1 QP (F to rounding)."""
    a = _scene("f1").build()
    b = _scene(boundary=[{"side": "bottom", "support": "clamp"}, {"side": "top", "traction": [0, -3.0]}]).build()
    assert np.array_equal(a.geometry.node_dofs, b.geometry.node_dofs)
    assert (a.K != b.K).nnz == 0 and (a.B != b.B).nnz == 0
    assert np.abs(a.F - b.F).max() <= 1e-14 * np.abs(a.F).max()


def test_update_reuses_the_assembly_for_loads():
    from dualfem.experiments.workspace import Workspace

    ws = Workspace("f2", {"N": 8, "remote_stress": [[0.0, 0.0], [0.0, 1.0]]})
    F1 = ws.qp.F.copy()
    ws.update(remote_stress=[[0.0, 0.0], [0.0, 2.0]])
    assert ws.assemblies == 1 and np.allclose(ws.qp.F, 2 * F1, rtol=1e-14, atol=0)
    ws.update(body_force=[0.0, 0.0], load_scale=0.5)
    assert ws.assemblies == 1 and np.allclose(ws.qp.F, F1, rtol=1e-14, atol=0)
    legacy = Workspace("f2", {"N": 8})
    legacy.setup(factorize=False)
    legacy.update(remote_stress=[[0.0, 0.0], [0.0, 1.0]])     # other supports: a new assembly, right dofs
    assert np.array_equal(legacy.qp.geometry.node_dofs, ws.qp.geometry.node_dofs)


SCENE_BAD = [
    ({"remote_stress": [[0, 0], [0, 1]], "load": "f1"}, r"load = 'f1'.*\[\[boundary\]\]"),
    ({"boundary": [{"side": "bottom", "support": "roller"}], "rotate_deg": 10.0}, r"roller.*rotate_deg"),
    ({"defects": [{"points": [[0.25, 0.5], [0.75, 0.5]], "face_pressure": "log(x - 0.5)"}]},
     r"defects\[0\]\.face_pressure"),
    ({"defects": [{"points": [[0.25, 0.5], [0.75, 0.5]], "face_pressure": [1, 2]}]}, r"defects\[0\]\.face_pressure"),
    ({"boundary": [{"side": "top", "traction": [1.0, 0]}]}, r"equilibrium"),
    ({"body_force": "[0, -1]"}, r"equilibrium"),
    ({"boundary": '[{"side": "left", "support": "clamp"}, {"side": "left", "support": "free"}]'}, r"twice"),
]


@pytest.mark.parametrize("keys, needle", SCENE_BAD)
def test_scene_refuses(keys, needle):
    with pytest.raises(InputError, match=needle):
        _scene(**keys).build()


def test_fractured_face_pressure_opens_every_crack():
    kw = {"cracks": 3, "mesh_size": 0.05, "tip_size": 0.05, "crack_length": 0.2, "min_gap": 0.1}
    qp = _scene("fractured", face_pressure=2.0, remote_stress=[[0.0, 0.0], [0.0, 0.0]], **kw).build()
    jump = qp.B @ _solve_qp(qp).x
    ids = qp.interface.defect_id
    assert all(jump[ids == k].max() > 0 for k in range(3)) and jump.min() >= -1e-12
    with pytest.raises(InputError, match="face_pressure"):
        _scene("fractured", face_pressure="foo", **kw)


def test_stress_grid_units_convert_the_new_keys():
    """The units axis (stress_grid.scene_in_units) keeps the physics of a scene with body force, traction and
    face pressure expressions: displacements x length, contact forces x stress x length."""
    from dualfem.core.scene import load_scene
    from dualfem.experiments.stress_grid import scene_in_units

    base = {"N": 8, "boundary": [{"side": "bottom", "support": "clamp"}, {"side": "top", "traction": ["x", "-3 - y"]}],
            "body_force": ["0.5*y", -2.0], "remote_stress": None,
            "defects": [{"points": [[0.25, 0.5], [0.75, 0.5]], "face_pressure": "-1 - x"}]}
    fs, fl = 1e6, 1e-3
    a = load_scene("f2", scene_in_units(base, 1.0, 1.0)).build()
    b = load_scene("f2", scene_in_units(base, fs, fl)).build()
    sa, sb = _solve_qp(a), _solve_qp(b)
    assert np.abs(sb.x - fl * sa.x).max() <= 1e-8 * fl * np.abs(sa.x).max()
    assert np.abs(sb.multipliers - fs * fl * sa.multipliers).max() <= 1e-8 * fs * fl * np.abs(sa.multipliers).max()
    assert sa.multipliers.max() > 0
