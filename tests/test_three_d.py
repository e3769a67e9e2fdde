"""3D scenes (problems/three_d): defect surfaces, node doubling and its checks, the vectorised P1
tetrahedron assembly against scikit-fem's, scene validation and the dispatch by ``dim``."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene

pytest.importorskip("gmsh")

from dualfem.problems.three_d.assemble import free_dofs, gradients, interface, stiffness  # noqa: E402
from dualfem.problems.three_d.cut import CutError, check_cut, cut  # noqa: E402
from dualfem.problems.three_d.geometry import parse_defects  # noqa: E402
from dualfem.problems.three_d.mesh import mesh_box  # noqa: E402

SHAPES = [
    {"shape": "disk", "center": [0.3, 0.5, 0.5], "normal": [0.2, 0.1, 1.0], "radius": 0.18},
    {"shape": "ellipse", "center": [0.75, 0.3, 0.3], "normal": [1, 0, 1], "axes": [0.08, 0.16], "direction": [0, 1, 0]},
    {"shape": "polygon", "points": [[0.6, 0.6, 0.75], [0.9, 0.6, 0.75], [0.9, 0.9, 0.75], [0.75, 0.8, 0.75]]},
    {"shape": "cap", "center": [0.72, 0.72, 0.05], "axis": [0, 0, 1], "curvature_radius": 0.25, "radius": 0.2},
]


@pytest.fixture(scope="module")
def four():
    """The box with one defect of every shape, meshed and cut."""
    surfaces = parse_defects(SHAPES, 1e-5, (1.0, 1.0, 1.0))
    m = mesh_box((1.0, 1.0, 1.0), surfaces, 0.09, 0.03)
    return surfaces, m, cut(m.points, m.tets, m.faces, surfaces)


def test_cut_doubles_interior_nodes_and_keeps_the_front(four):
    surfaces, m, c = four
    n0 = m.points.shape[1]
    assert np.array_equal(c.upper, n0 + np.arange(c.lower.size))
    assert np.allclose(c.points[:, c.upper], c.points[:, c.lower])
    assert np.intersect1d(c.lower, c.front).size == 0
    assert set(np.unique(c.defect_id)) == set(range(4)) == set(np.unique(c.front_id))
    # every node of each defect's triangles is either doubled or on its front; the front lies on the rim
    for k, f in enumerate(m.faces):
        nodes = np.unique(f)
        assert np.array_equal(np.sort(np.r_[c.lower[c.defect_id == k], c.front[c.front_id == k]]), nodes)
    rim = c.points[:, c.front[c.front_id == 0]].T - surfaces[0].center
    assert np.allclose(np.linalg.norm(rim - np.outer(rim @ surfaces[0].normal, surfaces[0].normal), axis=1), 0.18,
                       rtol=1e-6)
    # the ellipse's semi-axis a = 0.08 lies along its direction, b = 0.16 across; the polygon runs counter-
    # clockwise seen from +z, so its normal is +z (right-hand rule); the cap's normal at its apex is its axis
    e = c.points[:, c.front[c.front_id == 1]].T - surfaces[1].center
    d = np.array([0.0, 1.0, 0.0])
    assert np.abs(e @ d).max() == pytest.approx(0.08, rel=1e-2)
    assert np.abs(e @ np.cross(surfaces[1].normal, d)).max() == pytest.approx(0.16, rel=1e-2)
    assert np.allclose(surfaces[2].normal, [0, 0, 1])
    assert np.allclose(surfaces[3].normal_at(np.array([[0.72, 0.72, 0.30]])), [[0, 0, 1]])
    # the cut's own checks hold: no tetrahedron touches both copies, each copy has tetrahedra
    check_cut(c)
    count = np.bincount(c.tets.ravel(), minlength=c.points.shape[1])
    assert (count[c.lower] > 0).all() and (count[c.upper] > 0).all()


def test_plus_copies_lie_on_the_side_of_the_normal(four):
    """A tetrahedron with a face on a defect uses the "+" copies iff it lies on the normal's side."""
    surfaces, m, c = four
    base = np.arange(c.points.shape[1])
    base[c.upper] = c.lower
    copy = np.full(c.points.shape[1], -1)
    copy[c.lower] = c.upper
    orig = np.sort(base[c.tets], axis=0)
    checked = 0
    for k, f in enumerate(m.faces):
        keys = {tuple(sorted(t)) for t in f.T.tolist()}
        for corners in ([0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]):
            face = orig[corners]
            on = np.array([tuple(col) in keys for col in face.T.tolist()])
            doubled = copy[face] >= 0
            on &= doubled.any(axis=0)
            if not on.any():
                continue
            v = face[:, on][doubled[:, on].argmax(axis=0), np.arange(on.sum())]     # a doubled node of the face
            cen = c.points[:, c.tets[:, on]].mean(axis=1).T
            side = ((cen - c.points[:, v].T) * surfaces[k].normal_at(c.points[:, v].T)).sum(axis=1) > 0
            uses_plus = (c.tets[:, on] == copy[v]).any(axis=0)
            assert np.array_equal(side, uses_plus)
            checked += on.sum()
    assert checked >= 2 * c.lower.size


def test_normals_and_nodal_areas(four):
    surfaces, m, c = four
    for k, s in enumerate(surfaces):
        j = c.defect_id == k
        X = c.points[:, c.lower[j]].T
        exact = s.normal_at(X)
        assert np.allclose(np.linalg.norm(c.normals[:, j], axis=0), 1.0)
        cos = (c.normals[:, j].T * exact).sum(axis=1)
        assert cos.min() > (1 - 1e-12 if s.shape != "cap" else 0.99)
        # lumped areas: the interior nodes' weights plus the front's share make the meshed area
        assert 0.5 * c.area[k] < c.weights[j].sum() < c.area[k]
        assert c.area[k] == pytest.approx(s.area(), rel=0.05)


def test_cut_refuses_a_surface_the_mesh_does_not_carry():
    """Triangles that are not faces of the tetrahedra do not split the stars: refused with a clear error."""
    from skfem import MeshTet

    mt = MeshTet.init_tensor(*[np.linspace(0, 1, 7)] * 3)
    p, t = mt.p, mt.t.copy()
    g, vol = gradients(p, t)
    t[:, vol < 0] = t[[0, 2, 1, 3]][:, vol < 0]
    on = np.flatnonzero(np.isclose(p[2], 0.5) & (np.abs(p[0] - 0.5) < 0.34) & (np.abs(p[1] - 0.5) < 0.34))
    # a 5 x 5 patch of nodes on z = 0.5, triangulated with both diagonals of each square: crossing faces
    ij = np.rint(p[:2, on] * 6).astype(int)
    idx = {tuple(v): n for v, n in zip(ij.T.tolist(), on)}
    tri = []
    for a in range(1, 5):
        for b in range(1, 5):
            q = [idx[(a, b)], idx[(a + 1, b)], idx[(a + 1, b + 1)], idx[(a, b + 1)]]
            tri += [[q[0], q[1], q[2]], [q[0], q[2], q[3]], [q[1], q[3], q[0]]]
    surf = parse_defects([{"shape": "disk", "center": [0.5, 0.5, 0.5], "normal": [0, 0, 1], "radius": 0.3}],
                         1.0, (1.0, 1.0, 1.0))
    with pytest.raises(CutError):
        cut(p, t, [np.array(tri).T], surf)
    # a broken doubling is caught by check_cut
    c = cut(p, t, [np.array(tri[0::3] + tri[1::3]).T], surf)
    bad = c.tets.copy()
    k = np.flatnonzero(np.isin(bad, c.upper).any(axis=0))[0]
    corner = np.flatnonzero(~np.isin(bad[:, k], c.upper))[0]
    j = np.flatnonzero(c.upper == bad[np.isin(bad[:, k], c.upper), k][0])[0]
    bad[corner, k] = c.lower[j]
    with pytest.raises(CutError, match="both copies"):
        check_cut(type(c)(**{**c.__dict__, "tets": bad}))


def test_assembly_matches_scikit_fem():
    """The vectorised stiffness equals scikit-fem's linear_elasticity (same Lame parameters) to 1e-12,
    on a distorted mesh, with whole nodes and single components fixed."""
    from skfem import Basis, ElementTetP1, ElementVector, MeshTet
    from skfem.models.elasticity import linear_elasticity

    mt = MeshTet.init_tensor(*[np.linspace(0, 1, 5)] * 3)
    mt = MeshTet(mt.p + 0.04 * np.sin(5 * mt.p[[1, 2, 0]]), mt.t)
    lam, mu = 1.7e3, 0.9e3
    Ks = linear_elasticity(lam, mu).assemble(Basis(mt, ElementVector(ElementTetP1())))
    t = mt.t.copy()
    _, vol = gradients(mt.p, t)
    t[:, vol < 0] = t[[0, 2, 1, 3]][:, vol < 0]
    for fixed in (np.zeros((3, mt.p.shape[1]), bool), None):
        if fixed is None:
            fixed = np.zeros((3, mt.p.shape[1]), bool)
            fixed[:, np.isclose(mt.p[2], 0)] = True
            fixed[0, np.isclose(mt.p[0], 1)] = True
        nd = free_dofs(fixed)
        keep = nd.T.ravel() >= 0
        K = stiffness(mt.p, t, lam, mu, nd, int(keep.sum()))
        ref = Ks[keep][:, keep]
        assert K.has_canonical_format and K.format == "csc"
        assert abs(K - ref).max() <= 1e-12 * abs(ref).max()


def test_interface_term_and_B():
    """sum_j coef_j |jump_j|^2 and B x = nu . jump on hand-made jumps."""
    nd = free_dofs(np.zeros((3, 4), bool))
    lower, upper = np.array([0, 1]), np.array([2, 3])
    normals = np.array([[0.0, 0.6], [0.0, 0.0], [1.0, 0.8]])
    Ki, B, _ = interface(nd, lower, upper, normals, np.array([2.0, 3.0]), 12)
    x = np.arange(12.0) ** 1.5
    u = x.reshape(4, 3)
    jump = u[upper] - u[lower]
    assert x @ Ki @ x == pytest.approx(2 * jump[0] @ jump[0] + 3 * jump[1] @ jump[1])
    assert np.allclose(B @ x, (jump * normals.T).sum(axis=1))


@pytest.mark.parametrize("bad, match", [
    ({"defects": [{"shape": "disk", "center": [0.5, 0.5, 0.95], "normal": [1, 0, 0], "radius": 0.2}]},
     r"defects\[0\] \(disk\) is not strictly inside the box"),
    ({"defects": [{"shape": "disk", "center": [0.5, 0.5, 0.5], "normal": [0, 0, 1], "radius": 0.2},
                  {"shape": "disk", "center": [0.5, 0.5, 0.5], "normal": [1, 0, 0], "radius": 0.2}]},
     r"defects\[0\] and defects\[1\] intersect"),
    ({"defects": [{"shape": "polygon", "points": [[0.2, 0.2, 0.5], [0.8, 0.2, 0.5], [0.8, 0.8, 0.6],
                                                  [0.2, 0.8, 0.5]]}]}, "must be planar"),
    ({"defects": [{"shape": "polygon", "points": [[0.2, 0.2, 0.5], [0.8, 0.6, 0.5], [0.8, 0.2, 0.5],
                                                  [0.2, 0.9, 0.5]]}]}, "must be simple"),
    ({"defects": [{"shape": "ellipse", "center": [0.5] * 3, "normal": [0, 0, 1], "axes": [0.1, 0.2],
                   "direction": [0, 0, 2]}]}, "must not be parallel"),
    ({"defects": [{"shape": "cap", "center": [0.5] * 3, "axis": [0, 0, 1], "curvature_radius": 0.1,
                   "radius": 0.2}]}, "a cap is at most a hemisphere"),
    ({"defects": [{"shape": "disk", "center": [0.5] * 3, "normal": [0, 0, 0], "radius": 0.2}]}, "non-zero"),
    ({"defects": [{"shape": "disk", "center": [0.5] * 3, "normal": [0, 0, 1]}]}, "'radius' is missing"),
    ({"defects": [{"shape": "disk", "center": [0.5] * 3, "normal": [0, 0, 1], "radius": 0.1, "axes": [1, 2]}]},
     "unknown key 'axes'"),
    ({"defects": [{"shape": "sphere"}]}, "shape must be one of"),
    ({"mesh_size": 1e-3}, r"tetrahedra \(limit"),
    ({"mesh_size": 0.1, "tip_size": 1e-4}, "tip_size must be in"),
    ({"mesh_size": 0.1, "surface_size": 1e-3}, r"surface_size must be in \[0\.0"),
    ({"mesh_size": 0.1, "surface_size": 0.2}, r"surface_size must be in \[0, mesh_size\]"),
    ({"mesh": "structured"}, "mesh must be gmsh"),
    ({"rotate_axis": [0, 0, 0]}, "rotate_axis"),
    ({"nu": 0.5}, "nu"),
    ({"delta": 1e-20}, "too small"),
    ({"load": "[1, 2]"}, "load"),
])
def test_bad_scenes_are_refused_before_meshing(bad, match):
    with pytest.raises(InputError, match=match):
        load_scene("three_d", bad)


def test_dim_routes_scene_files(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('dim = 3\nmesh_size = 0.25\n[[defects]]\nshape = "disk"\ncenter = [0.5, 0.5, 0.5]\n'
                 'normal = [0, 0, 1]\nradius = 0.3\n', encoding="utf-8")
    assert load_scene(str(f)).name == "three_d"
    assert load_scene("three_d", {"dim": "3"}).name == "three_d"
    assert load_scene("f2", {"dim": "2"}).name == "thin_defect"
    two = tmp_path / "two.toml"
    two.write_text('N = 8\n', encoding="utf-8")
    assert load_scene(str(two)).name == "thin_defect"
    with pytest.raises(InputError, match="this scene's problem is 2D"):
        load_scene("f2", {"dim": 3})
    with pytest.raises(InputError, match="dim .* must be one of 2, 3"):
        load_scene(str(f), {"dim": 4})
    with pytest.raises(InputError, match="dim must be 3"):
        load_scene("three_d", {"dim": 2})


def test_export_writes_the_3d_maps(tmp_path):
    from dualfem.core.qp import QP

    qp = load_scene("three_d", {"N": 6}).build()
    for suffix in (".npz", ".mat"):
        path = qp.save(tmp_path / f"q{suffix}")
        d = np.load(path) if suffix == ".npz" else None
        back = QP.load(path)
        assert back.geometry is not None and back.geometry.dim == 3
        assert back.geometry.nodes.shape == (3, qp.geometry.nodes.shape[1])
        assert back.geometry.cells.shape[0] == 4
        assert np.shape(back.interface.normals) == (qp.m, 3)
        assert abs(back.K - qp.K).max() == 0 and np.array_equal(back.interface.upper, qp.interface.upper)
        if d is not None:
            assert d["map_nodes"].shape[0] == 3 and d["map_defect_normals"].shape == (qp.m, 3)
