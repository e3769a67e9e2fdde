"""Quadratic tetrahedra in 3D (``element = "P2"``, problems/three_d/quadratic.py, problems/_quadratic3d.py): the
P2 stiffness against scikit-fem's, the patch test (a uniform stress reproduced exactly, with and without a closed
penny), the penny's opening closer than P1's on the same mesh, the refusals and the outputs."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene

pytest.importorskip("gmsh")
pytest.importorskip("skfem")

from dualfem.experiments.runner import run  # noqa: E402
from dualfem.post.fields3d import VOIGT, defect_fields3d, stresses3d  # noqa: E402
from dualfem.problems._quadratic3d import quadratic_tets  # noqa: E402
from dualfem.problems.three_d import quadratic as p2  # noqa: E402
from dualfem.problems.three_d.assemble import free_dofs  # noqa: E402

E, NU = 1000.0, 0.3
DISK = {"shape": "disk", "center": [2.0, 2.0, 2.0], "normal": [0.0, 0.0, 1.0], "radius": 1.0}


def box(stress, defects, **extra):
    """A 4 x 4 x 4 box under a remote stress (no supports), coarse, P2."""
    return load_scene("penny", {"width": 4.0, "depth": 4.0, "height": 4.0, "E": E, "nu": NU, "delta": 1e3,
                                "mesh_size": 1.5, "tip_size": 0.5, "remote_stress": stress, "defects": defects,
                                "element": "P2", **extra})


def test_p2_stiffness_equals_scikit_fem():
    from skfem import MeshTet

    m = MeshTet.init_tensor(np.linspace(0, 1, 3), np.linspace(0, 2, 3), np.linspace(0, 1, 2))
    p, t = m.p, m.t.copy()
    vol = np.einsum("it,it->t", np.cross((p[:, t[1]] - p[:, t[0]]).T, (p[:, t[2]] - p[:, t[0]]).T).T,
                    p[:, t[3]] - p[:, t[0]])
    t[[1, 2]] = np.where(vol < 0, t[[2, 1]], t[[1, 2]])              # positively oriented, as the mesh module gives
    q = quadratic_tets(p, t)
    nd = free_dofs(np.zeros((3, q.points.shape[1]), bool))
    K = p2.stiffness(q.points, q.cells, 2.0, 3.0, nd, 3 * q.points.shape[1])
    R = p2.skfem_stiffness(p, t, 2.0, 3.0)
    assert K.shape == R.shape == (3 * q.points.shape[1],) * 2
    assert abs(K - R).max() <= 1e-13 * abs(R).max()
    assert np.allclose(q.points[:, q.cells[4]], 0.5 * (p[:, t[0]] + p[:, t[1]]))   # VTK's tetra10 edge order
    assert np.allclose(q.points[:, q.cells[6]], 0.5 * (p[:, t[0]] + p[:, t[2]]))


SIGMA = [[1.0, 0.3, 0.0], [0.3, -0.5, 0.0], [0.0, 0.0, -2.0]]     # no shear on the planes z = const


@pytest.mark.parametrize("solver", ["pdas", "mprgp"])
@pytest.mark.parametrize("defects", [[], [DISK]], ids=["uncracked", "closed_penny"])
def test_patch_uniform_stress_is_exact(defects, solver):
    qp = box(SIGMA, defects).build()
    assert qp.geometry.cells.shape[0] == 10 and qp.geometry.quadratic
    # the closed penny's P2 vertex pairs carry no contact force (the consistent P2 force of a uniform pressure is
    # 0 at a triangle's corners): a degenerate QP, whose exact answers the certificate bounds through the face's
    # exact point (dualfem/numerics/degenerate.py; pdas's duality-gap bound alone is 3.8e-9)
    sol = run(solver, qp)
    assert str(sol.status) == "solved"
    assert sol.info["certificate"]["value"] <= 1e-12
    st = stresses3d(qp, sol.x)
    for k, (i, j) in zip(VOIGT, ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))):
        assert np.allclose(st[k], SIGMA[i][j], atol=1e-8), k
    if defects:
        d = defect_fields3d(qp, sol.x, sol.multipliers)
        assert np.abs(d["jump"]).max() < 1e-10
        corner = np.isin(qp.interface.lower, qp.geometry.cells[:4])
        mu = np.asarray(sol.multipliers)
        assert corner.any() and (~corner).any() and mu.min() >= -1e-12
        assert np.abs(mu[corner]).max() < 1e-9 * mu.max()      # the consistent P2 force of a uniform pressure
        assert mu[~corner].min() > 0.1 * mu.max()               # is 0 at the corners, A/3 per face at mid-edges
        assert np.allclose(d["pressure"], 2.0, rtol=1e-9)       # the recovered pressure: -sigma_zz at every pair


def opening_error(qp, x) -> float:
    """Relative L2 error (nodal weights) of the penny's opening over r <= 0.8 (the closed form, infinite body)."""
    lo = qp.interface.lower
    X = qp.geometry.nodes[:, lo] - 5.0
    r = np.hypot(X[0], X[1])
    exact = 8 * (1 - NU ** 2) / (np.pi * E) * np.sqrt(np.maximum(1 - r ** 2, 0.0))
    k = r <= 0.8
    w = qp.weights[k]
    return float(np.sqrt(np.sum(w * ((qp.B @ x)[k] - exact[k]) ** 2) / np.sum(w * exact[k] ** 2)))


def test_p2_penny_opening_beats_p1_on_the_same_mesh():
    errors = {}
    for element in ("P1", "P2"):
        qp = load_scene("penny", {"mesh_size": 2.5, "tip_size": 0.5, "element": element}).build()
        sol = run("pdas", qp)
        assert str(sol.status) == "solved"
        errors[element] = opening_error(qp, sol.x)
    assert errors["P2"] < 0.4 * errors["P1"]


def test_p1_is_the_default_and_unchanged():
    a = load_scene("penny", {"mesh_size": 2.5, "tip_size": 0.5}).build()
    b = load_scene("penny", {"mesh_size": 2.5, "tip_size": 0.5, "element": "P1"}).build()
    assert "element" not in a.params and a.geometry.cells.shape[0] == 4
    assert (a.K != b.K).nnz == 0 and np.array_equal(a.F, b.F) and (a.B != b.B).nnz == 0
    c = load_scene("penny", {"mesh_size": 2.5, "tip_size": 0.5, "element": "P2"})
    assert c.build().params["element"] == "P2"
    assert c.size_estimate()[0] > 5 * load_scene("penny", {"mesh_size": 2.5, "tip_size": 0.5}).size_estimate()[0]


@pytest.mark.parametrize("keys, words", [
    ({"element": "P3"}, "element must be one of 'P1', 'P2'"),
    ({"element": "P2-quarter-point"}, "2D only"),
    ({"element": "P2", "refine": "adaptive", "target_error": 0.1, "max_unknowns": 20000}, "refine = 'adaptive'"),
    ({"element": "P2", "friction": "coulomb", "friction_coefficient": 0.3}, "friction"),
])
def test_refusals(keys, words):
    with pytest.raises(InputError, match=words):
        load_scene("penny", keys)


def test_legacy_top_load_and_clamp_on_p2():
    """The legacy scene (bottom clamped, top traction): a clamped column under a uniform pull; P2 loads carry the
    whole force (sum of the nodal forces = traction x area)."""
    pr = load_scene("three_d", {"N": 3, "load": 2.0, "element": "P2"})
    qp = pr.build()
    assert qp.F.sum() == pytest.approx(2.0 * 1.0, rel=1e-12)
    sol = run("pdas", qp)
    assert str(sol.status) == "solved"


def test_outputs_on_p2(tmp_path):
    from dualfem.post.sif_outputs import sif_result
    from dualfem.post.vtk import write_vtu

    qp = load_scene("penny", {"mesh_size": 2.5, "tip_size": 0.5, "element": "P2"}).build()
    sol = run("pdas", qp)
    path = write_vtu(tmp_path / "p2.vtu", qp, sol)
    import meshio

    m = meshio.read(path)
    assert m.cells[0].type == "tetra10" and m.point_data["displacement"].shape == (qp.geometry.nodes.shape[1], 3)
    sif, record = sif_result(qp, sol)          # the interaction integral at the P2 tetrahedra's 4 points each
    exact = 2 / np.sqrt(np.pi)                 # the penny under tension 1, radius 1: K_I = 2 sigma sqrt(a / pi)
    assert sif.method == "interaction" and record["method"] == "interaction" and len(record["K_I"]) == sif.K_I.size
    assert abs(sif.K_I.mean() / exact - 1) < 0.03 and np.abs(sif.K_II).max() < 0.05 * exact
    p1 = load_scene("penny", {"mesh_size": 2.5, "tip_size": 0.5}).build()     # the same mesh, P1: -10 %
    k1, _ = sif_result(p1, run("pdas", p1))
    assert abs(sif.K_I.mean() / exact - 1) < 0.3 * abs(k1.K_I.mean() / exact - 1)


def test_geometry_part_quadratic_cells_need_a_quadratic_element():
    from dualfem.core.parts import GeometryPart

    qp = load_scene("penny", {"mesh_size": 2.5, "tip_size": 0.5, "element": "P2"}).build()
    g = qp.geometry
    assert g.element == "P2" and g.quadratic
    g.validate(qp.n)
    with pytest.raises(InputError, match="geometry.cells must have shape"):
        GeometryPart(3, g.nodes, g.cells, g.node_dofs).validate(qp.n)       # 10-node cells, element P1


def test_p2_rotation_leaves_the_energy_and_contact_set():
    """A closed inclined penny under compression and shear, rotated with its loads: the same energy and contact
    set (the P2 nodes, supports and consistent loads rotate with the body)."""
    out = []
    for rot in (0.0, 30.0):
        qp = box([[0, 0, 0.3], [0, 0, 0], [0.3, 0, -1]], [{**DISK, "normal": [0.0, 0.3, 1.0]}], delta=1.0,
                 rotate_deg=rot, rotate_axis=[1, 1, 0]).build()
        sol = run("pdas", qp)
        assert str(sol.status) == "solved"
        out.append((float(0.5 * sol.x @ (qp.K @ sol.x) - qp.F @ sol.x), int(np.sum(sol.multipliers > 0))))
    assert out[0][1] == out[1][1] > 0
    assert out[1][0] == pytest.approx(out[0][0], rel=1e-10)


def test_size_guard_knows_p2_before_meshing():
    """The memory check reads the P2 estimate before anything is meshed: a tip size that P1 affords is refused
    for P2 on one line naming the element (no gmsh call: the scene is never meshed here)."""
    from dualfem.numerics.memory import check_fits

    keys = {"tip_size": 0.02}
    p1, quad = load_scene("penny", keys), load_scene("penny", {**keys, "element": "P2"})
    assert quad.size_estimate()[0] > 7 * p1.size_estimate()[0]
    check_fits(p1, max_bytes=4e9, backend="pardiso")
    with pytest.raises(InputError, match="element='P2'.*needs about"):
        check_fits(quad, max_bytes=4e9, backend="pardiso")
    assert "cut" not in quad.shared.data


def test_estimator_refuses_p2():
    from dualfem.numerics.estimator import estimate

    qp = box(SIGMA, []).build()
    with pytest.raises(InputError, match=r"the estimator takes P1 \(2D, 3D\) and P2 triangles"):
        estimate(qp, np.zeros(qp.n))


def test_face_pressure_is_remote_tension_by_superposition():
    """Remote tension sigma on the box = the uniform field (no jump) + the crack faces pressed apart by sigma: with
    consistent P2 forces on the faces the two openings agree to rounding (lumped forces were 13 % off here)."""
    zero = [[0.0] * 3] * 3
    tension = box([[0, 0, 0], [0, 0, 0], [0, 0, 1.0]], [DISK]).build()
    pressed = box(zero, [{**DISK, "face_pressure": 1.0}]).build()
    a, b = (run("pdas", q) for q in (tension, pressed))
    ja, jb = tension.B @ a.x, pressed.B @ b.x
    assert ja.min() > 0 and np.abs(ja - jb).max() <= 1e-8 * ja.max()
