"""Quadratic thin-defect elements (scene key ``element``; problems/_quadratic.py, problems/thin_defect/element.py)."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.errors import InputError
from dualfem.experiments.runner import run
from dualfem.problems import _quadratic as q2
from dualfem.scene import load_scene

E, NU = 1000.0, 0.3


def _nodal(qp, x):
    nd = qp.geometry.node_dofs
    u = np.zeros(nd.shape)
    u[nd >= 0] = np.asarray(x)[nd[nd >= 0]]
    return u


def _box(element, stress, defects, L=4.0, h=1.0, tip=0.5, **extra):
    return load_scene("f2", {"mesh": "gmsh", "width": L, "height": L, "E": E, "nu": NU, "delta": 1e3,
                             "defects": defects, "remote_stress": stress, "mesh_size": h, "tip_size": tip,
                             "element": element, **extra})


def test_p1_default_is_the_same_qp():
    a, b = load_scene("f2", {"N": 8}).build(), load_scene("f2", {"N": 8, "element": "P1"}).build()
    assert (a.K != b.K).nnz == 0 and np.array_equal(a.F, b.F) and (a.B != b.B).nnz == 0
    assert "element" not in a.params and "element" not in b.params and a.geometry.element == "P1"


@pytest.mark.parametrize("el", ["P2", "P2-quarter-point"])
@pytest.mark.parametrize("stress, defects", [([[0.3, 0.2], [0.2, -0.5]], []),                 # no crack
                                             ([[-1.0, 0.0], [0.0, -1.0]], [{"points": [[1.2, 2.1], [2.8, 1.9]]}])])
def test_patch_uniform_stress_is_reproduced(el, stress, defects):
    """A remote stress on a free box (a closed crack under pure compression): the linear displacement of the
    uniform stress is in the P2 (and isoparametric) space, so the answer is it, up to a rigid motion."""
    qp = _box(el, stress, defects).build()
    sol = run("pdas", qp)
    assert str(sol.status) == "solved"
    u, X = _nodal(qp, sol.x), qp.geometry.nodes
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    s = np.asarray(stress, float)
    eps = (s - lam / (2 * (lam + mu)) * np.trace(s) * np.eye(2)) / (2 * mu)       # plane strain
    r = u - eps @ X
    rigid = np.column_stack([np.tile([1.0, 0.0], X.shape[1]), np.tile([0.0, 1.0], X.shape[1]),
                             np.column_stack([-X[1], X[0]]).ravel()])
    coef = np.linalg.lstsq(rigid, r.T.ravel(), rcond=None)[0]
    assert np.abs(r.T.ravel() - rigid @ coef).max() <= 1e-10 * np.abs(eps @ X).max()
    if defects:     # every pair (vertex and mid-edge) closed, the contact pressure = 1 (the compression)
        assert qp.m > 0 and np.abs(qp.B @ sol.x).max() <= 1e-12
        assert np.allclose(qp.pressure(sol.multipliers), 1.0, rtol=1e-8)


def _opening_error(el: str) -> float:
    """Relative L2 error of the Griffith opening's shape over |s| <= 0.8 a (a = 1, box 20 a): against the closed
    form times the factor fitted to the opening (the finite box's bias, about 1 %, is such a factor)."""
    qp = _box(el, [[0.0, 0.0], [0.0, 1.0]], [{"points": [[9.0, 10.0], [11.0, 10.0]]}], L=20.0, h=2.0,
              tip=0.2).build()
    sol = run("pdas", qp)
    it = qp.interface
    u = _nodal(qp, sol.x).T
    op = np.sum((u[it.upper] - u[it.lower]) * it.normals, axis=1)
    s = it.s - 1.0
    ex = 4 * (1 - NU ** 2) / E * np.sqrt(np.maximum(1 - s * s, 0))
    k, w = np.abs(s) <= 0.8, qp.weights
    ex *= np.sum(w[k] * op[k] * ex[k]) / np.sum(w[k] * ex[k] ** 2)     # the box's bias: a factor on the opening
    return float(np.sqrt(np.sum(w[k] * (op[k] - ex[k]) ** 2) / np.sum(w[k] * ex[k] ** 2)))


def test_griffith_opening_p2_beats_p1_on_the_same_mesh():
    p1, p2, qp2 = _opening_error("P1"), _opening_error("P2"), _opening_error("P2-quarter-point")
    assert p2 < 0.7 * p1 and qp2 < 0.5 * p2, (p1, p2, qp2)


def test_quarter_point_mapping():
    pr = _box("P2-quarter-point", [[0.0, 0.0], [0.0, 1.0]], [{"points": [[1.0, 2.0], [3.0, 2.0]]}])
    qp = pr.build()
    from dualfem.problems.thin_defect.element import basis
    b = basis(qp.geometry.nodes, qp.geometry.cells, True)
    lin = basis(qp.geometry.nodes, qp.geometry.cells, False)
    det, det1 = b.mesh.mapping().detDF(b.quadrature[0]), lin.mesh.mapping().detDF(lin.quadrature[0])
    # det J of the isoparametric map keeps the sign of the straight cell's (cells are stored with sorted ids,
    # either orientation) at every quadrature point: the quarter-point cells are not folded
    assert np.all(det * np.sign(det1) > 0) and np.any(det != det1)
    X, nv = qp.geometry.nodes, int(qp.geometry.cells.max()) + 1
    edges, _ = q2.edge_table(qp.geometry.cells)
    tips = qp.interface.front
    moved = 0
    for t in tips:
        for e in np.flatnonzero((edges == t).any(axis=0)):
            other = edges[0, e] + edges[1, e] - t
            assert np.allclose(X[:, nv + e], 0.75 * X[:, t] + 0.25 * X[:, other])   # at L/4 from the tip
            moved += 1
    assert moved >= 8
    far = ~np.isin(edges, tips).any(axis=0)
    assert np.allclose(X[:, nv:][:, far], 0.5 * (X[:, edges[0, far]] + X[:, edges[1, far]]))


def test_crack_edge_weights_and_pairs():
    P = np.array([[0.0, 1.0, 0.5], [0.0, 0.0, 0.0]])
    assert np.allclose(q2.edge_weights(P, np.array([[0], [2], [1]]), 3), [1 / 6, 1 / 6, 2 / 3])
    P[0, 2] = 0.25                                                        # quarter point, the tip first
    assert np.allclose(q2.edge_weights(P, np.array([[0], [2], [1]]), 3), [0.0, 1 / 3, 2 / 3])
    F = np.array([[0.0, 1, 0, 0.5, 0.5, 0], [0, 0, 1, 0, 0.5, 0.5], [0, 0, 0, 0, 0, 0]])
    w = q2.face_weights(F, np.arange(6).reshape(6, 1), 6)
    assert np.allclose(w, [1 / 24] * 3 + [1 / 8] * 3) and np.isclose(w.sum(), 0.5)
    qp = load_scene("f2", {"N": 8, "element": "P2"}).build()
    it = qp.interface
    assert qp.m == 2 * 3 + 1 and np.all(it.weights > 0) and np.isclose(it.weights.sum(), 0.5 - 2 * 0.125 / 6)
    assert np.all(np.diff(it.s) > 0) and not np.isin(it.front, np.r_[it.upper, it.lower]).any()
    assert np.allclose(it.normals, [0.0, 1.0])


@pytest.mark.parametrize("extra, words", [
    ({"element": "P3"}, "element must be one of 'P1', 'P2', 'P2-quarter-point'"),
])
def test_refusals(extra, words):
    with pytest.raises(InputError, match=words.replace("(", r"\(")):
        load_scene("f2", {"N": 8, **extra}).build()


def test_p1_post_processing_refuses_p2():
    from dualfem.post.sif import parts

    qp = load_scene("f2", {"N": 8, "element": "P2"}).build()
    with pytest.raises(InputError, match="need element = 'P1'"):
        parts(qp)


def _griffith_field(qp, sigma=1.0):
    """x with the closed-form Griffith opening 4 (1 - nu^2) sigma / E sqrt(a^2 - s^2) split over the two faces of
    every crack pair (a = 1, plane strain), every other unknown 0."""
    it = qp.interface
    s = it.s - 1.0
    op = 4 * (1 - NU ** 2) * sigma / E * np.sqrt(np.maximum(1 - s * s, 0))
    x = np.zeros(qp.n)
    for c in range(2):
        x[it.plus_dofs[:, c]] = 0.5 * op * it.normals[:, c]
        x[it.minus_dofs[:, c]] = -0.5 * op * it.normals[:, c]
    return x


def test_p2_sif_formulas_on_the_closed_form_jumps():
    """K from the exact Griffith jumps at the pairs of a quarter-point mesh: the series fit within 2e-3 of
    sigma sqrt(pi a), the quarter-point formula within its truncation L / (8 a); K_II = 0; stress_intensity picks
    the series fit."""
    from dualfem.post.sif_outputs import stress_intensity
    from dualfem.post.sif_quarter import quarter_point, series_fit

    qp = _box("P2-quarter-point", [[0.0, 0.0], [0.0, 1.0]], [{"points": [[9.0, 10.0], [11.0, 10.0]]}], L=20.0,
              h=2.0, tip=0.1).build()
    x = _griffith_field(qp)
    k0 = np.sqrt(np.pi)
    s, q = series_fit(qp, x), quarter_point(qp, x)
    assert np.abs(s.K_I / k0 - 1).max() < 2e-3 and np.abs(s.K_II).max() < 1e-9
    assert np.abs(q.K_I / k0 - 1).max() < 0.15 * q.radius.max()       # its truncation: + L / (8 a)
    assert np.abs(q.K_II).max() < 1e-9
    assert stress_intensity(qp, x).method == "series"
    with pytest.raises(InputError, match="reach must be"):
        series_fit(qp, x, reach=0.9)


def test_p2_sif_refusals():
    from dualfem.post.sif_outputs import stress_intensity

    p2 = load_scene("f2", {"N": 8, "element": "P2"}).build()
    with pytest.raises(InputError, match="need element = 'P2-quarter-point'"):
        stress_intensity(p2, np.zeros(p2.n), method="quarter-point")
    with pytest.raises(InputError, match="need element = 'P1'"):
        stress_intensity(p2, np.zeros(p2.n), method="interaction")
    p1 = load_scene("f2", {"N": 8}).build()
    with pytest.raises(InputError, match="need element = 'P2' or 'P2-quarter-point'"):
        stress_intensity(p1, np.zeros(p1.n), method="series")


@pytest.mark.parametrize("keys", [
    {"load": "f1"}, {"load": "f3", "rotate_deg": 30.0},
    {"boundary": [{"side": "bottom", "support": "clamp"}, {"side": "top", "traction": ["0.5 * x", "1 + y * x"]},
                  {"side": "left", "traction": [1.0, "y * y"]}], "body_force": ["x * y", -2.0]},
])
def test_p2_loads_have_the_p1_resultants(keys):
    """Consistent nodal forces integrate the same tractions and body force: the P2 load's net force and moment
    (about the origin) equal P1's on the same mesh (both exact for these polynomials, up to the Gauss rules)."""
    out = []
    for el in ("P1", "P2-quarter-point"):
        pr = load_scene("f2", {"N": 4, "element": el, **keys})
        pr.build()
        F, X = pr.nodal_load(), pr.cut()[1] if el == "P1" else pr._delta_free()["maps"]["nodes"]
        out.append(np.r_[F.sum(axis=1), np.sum(X[0] * F[1] - X[1] * F[0])])
    assert np.allclose(out[0], out[1], rtol=1e-9, atol=1e-12 * np.abs(out[0]).max()), out


def test_a_p2_qp_file_keeps_its_element(tmp_path):
    from dualfem.qp import QP

    qp = load_scene("f2", {"N": 4, "element": "P2-quarter-point"}).build()
    back = QP.load(qp.save(tmp_path / "p2.npz"))
    assert back.geometry.element == "P2-quarter-point" and back.geometry.nodes.shape == qp.geometry.nodes.shape
    assert QP.load(load_scene("f2", {"N": 4}).build().save(tmp_path / "p1.npz")).geometry.element == "P1"


def test_p2_friction_scales_the_slip():
    """A closed crack at 30 degrees under compression and shear, all of it slipping: Coulomb's slip is the
    frictionless one times (|tau| - mu sigma_n) / |tau| (the closed forms' ratio; the box's bias cancels)."""
    stress = [[0.0, 0.5], [0.5, -1.0]]
    crack = [{"points": [[9.1339746, 9.5], [10.8660254, 10.5]]}]
    slips = []
    for fr in ({}, {"friction": "coulomb", "friction_coefficient": 0.1}):
        qp = _box("P2-quarter-point", stress, crack, L=20.0, h=2.0, tip=0.1, **fr).build()
        sol = run("pdas", qp)
        assert str(sol.status) == "solved" and len(qp.blocks) == int(bool(fr))
        it = qp.interface
        u = _nodal(qp, sol.x).T
        slips.append(np.sum((u[it.upper] - u[it.lower]) * it.tangents[:, 0, :], axis=1))
    t, n = np.array([np.cos(np.pi / 6), 0.5]), np.array([-0.5, np.cos(np.pi / 6)])
    tau, sn = t @ np.array(stress) @ n, n @ np.array(stress) @ n
    ratio = (abs(tau) + 0.1 * sn) / abs(tau)
    k = np.abs(slips[0]) > 0.2 * np.abs(slips[0]).max()
    assert 0 < ratio < 1 and np.allclose(slips[1][k], ratio * slips[0][k], rtol=2e-3)


def test_p2_face_pressure_is_remote_tension_by_superposition():
    """A crack under face pressure p in an unloaded free box opens as under the remote tension p (the uniform
    field has no jump): the same openings at every pair, vertex and mid-edge."""
    crack = [[1.2, 2.1], [2.8, 1.9]]
    qa = _box("P2-quarter-point", [[0.0, 0.0], [0.0, 0.0]], [{"points": crack, "face_pressure": 3.0}]).build()
    n = np.array([0.2, 1.6]) / np.hypot(0.2, 1.6)                 # the crack's normal
    qb = _box("P2-quarter-point", (3.0 * np.outer(n, n)).tolist(), [{"points": crack}]).build()
    oa, ob = qa.B @ run("pdas", qa).x, qb.B @ run("pdas", qb).x
    assert oa.min() > 0 and np.allclose(oa, ob, rtol=1e-8, atol=1e-10 * oa.max())


def test_p2_vtu_writes_quadratic_cells_with_the_quarter_points(tmp_path):
    """VTU of a P2 scene: one ``triangle6`` cell per triangle over every P2 node (vertices, then the mid-edge nodes
    of (0, 1), (1, 2), (2, 0) as VTK orders them), the quarter-point nodes where the QP has them, and the
    displacement of every node; a QP whose mid-edge nodes are not on their edges is refused."""
    import dataclasses

    import meshio

    from dualfem.post.vtk import to_meshio, write_vtu

    qp = _box("P2-quarter-point", [[0.0, 0.0], [0.0, 1.0]], [{"points": [[1.0, 2.0], [3.0, 2.0]]}]).build()
    sol = run("pdas", qp)
    m = to_meshio(qp, sol)
    tri = m.cells[0]
    g = qp.geometry
    assert tri.type == "triangle6" and tri.data.shape == (g.cells.shape[1], 6)
    assert np.array_equal(tri.data[:, :3], g.cells.T)
    assert np.array_equal(np.unique(tri.data), np.arange(g.nodes.shape[1]))
    P = m.points[:, :2]
    t = []
    for k, (a, b) in enumerate(((0, 1), (1, 2), (2, 0))):
        pa, pb, pm = P[tri.data[:, a]], P[tri.data[:, b]], P[tri.data[:, 3 + k]]
        d = pb - pa
        t.append(np.sum((pm - pa) * d, axis=1) / np.sum(d * d, axis=1))
        assert np.allclose((pm - pa)[:, 0] * d[:, 1] - (pm - pa)[:, 1] * d[:, 0], 0, atol=1e-12)
    t = np.concatenate(t)
    assert np.isclose(t, 0.5).sum() > 0 and (np.isclose(t, 0.25) | np.isclose(t, 0.75)).sum() >= 2 * 4  # tip fans
    assert np.allclose(m.point_data["displacement"][:, :2], _nodal(qp, sol.x).T)
    back = meshio.read(write_vtu(tmp_path / "p2.vtu", qp, sol))
    assert back.cells[0].type == "triangle6" and np.array_equal(back.cells[0].data, tri.data)
    nv = g.cells.max() + 1
    bad = g.nodes.copy()
    bad[:, nv:] = bad[:, nv:][:, ::-1]                          # mid-edge nodes in the wrong order
    qp.geometry = dataclasses.replace(g, nodes=bad)
    with pytest.raises(InputError, match="not on their edges"):
        to_meshio(qp, sol)


def test_mid_edge_pairs_take_a_repeated_edge_once():
    """The generic pairing (3D gives each interior crack edge twice, once per face): the same pairs either way,
    and an edge whose two vertices are tips / front nodes is not a pair."""
    pr = load_scene("f2", {"N": 8})
    c, _ = pr.cut()
    edges, _ = q2.edge_table(c.triangles)
    from dualfem.problems.thin_defect.element import crack_edges
    ce = crack_edges(c)
    once, twice = q2.mid_edge_pairs(c, edges, ce), q2.mid_edge_pairs(c, edges, np.hstack([ce, ce[::-1]]))
    assert np.array_equal(once.lower, twice.lower) and np.array_equal(once.upper, twice.upper)
    assert np.array_equal(once.edge, twice.edge) and once.lower.size == ce.shape[1]
    assert q2.mid_edge_pairs(c, edges, c.tips[:2].reshape(2, 1)).lower.size == 0       # both ends single
