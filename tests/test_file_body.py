"""Bodies from mesh and geometry files (problems/file_body): the round trip of box scenes through .msh files,
the groups, the cut of edge cracks, the refusals."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("meshio")
pytest.importorskip("gmsh")

import meshio  # noqa: E402

from dualfem.errors import InputError  # noqa: E402
from dualfem.problems.file_body.write import write_msh  # noqa: E402
from dualfem.registry import get_problem  # noqa: E402
from dualfem.scene import load_scene  # noqa: E402


def _same_qp(a, b) -> None:
    for M, N in ((a.K, b.K), (a.B, b.B)):
        assert M.shape == N.shape
        assert abs(M - N).max() <= 1e-12 * abs(M).max()
    assert np.allclose(a.F, b.F, rtol=0, atol=1e-12 * np.abs(a.F).max())
    assert np.allclose(a.weights, b.weights, rtol=1e-12)


@pytest.mark.parametrize("version", [2.2, 4.1])
def test_round_trip_2d(tmp_path, version):
    """A 2D thin_defect gmsh scene written as .msh (MSH 2 and 4) and read back gives the same K, F, B."""
    boundary = [{"side": "bottom", "support": "clamp"}, {"side": "top", "traction": [1.0, 10.0]}]
    defects = [{"points": [[0.3, 0.5], [0.7, 0.55]]}, {"points": [[0.2, 0.2], [0.4, 0.3], [0.5, 0.2]]}]
    box = get_problem("thin_defect")(mesh="gmsh", mesh_size=0.08, tip_size=0.03, defects=defects, boundary=boundary)
    pts, tri, dn = box._reference_mesh()
    sides = box._box_sides()
    groups = {f"crack{k}": np.vstack([d[:-1], d[1:]]) for k, d in enumerate(dn)}
    groups |= {"base": sides["bottom"], "lid": sides["top"]}
    write_msh(tmp_path / "box.msh", pts, tri, groups, version)
    mine = get_problem("file_body")(mesh_file=str(tmp_path / "box.msh"),
                                    defects=[{"group": "crack0"}, {"group": "crack1"}],
                                    boundary=[{"group": "base", "support": "clamp"},
                                              {"group": "lid", "traction": [1.0, 10.0]}])
    a, b = box.build(), mine.build()
    _same_qp(a, b)
    assert np.array_equal(a.interface.upper, b.interface.upper)
    assert np.allclose(a.interface.s, b.interface.s)


@pytest.mark.parametrize("version", [2.2, 4.1])
def test_round_trip_3d(tmp_path, version):
    """A 3D three_d scene (an inclined disk) written as .msh and read back gives the same K, F, B."""
    from dualfem.problems.three_d.mesh import mesh_box

    boundary = [{"side": "bottom", "support": "clamp"}, {"side": "top", "traction": [0.0, 1.0, 10.0]}]
    disk = {"shape": "disk", "center": [0.5, 0.5, 0.5], "normal": [0.3, 0.0, 1.0], "radius": 0.25}
    box = get_problem("three_d")(mesh_size=0.25, tip_size=0.12, defects=[disk], boundary=boundary)
    m = mesh_box(box.box, box._surfaces, box.mesh_size, box.tip_size, box.surface_size)
    faces = m.faces[0].copy()
    P = m.points[:, faces]
    cr = np.cross((P[:, 1] - P[:, 0]).T, (P[:, 2] - P[:, 0]).T)
    flip = (cr * box._surfaces[0].normal_at(P.mean(axis=1).T)).sum(axis=1) < 0
    faces[[0, 1]] = np.where(flip, faces[[1, 0]], faces[[0, 1]])      # the file orders each triangle by the normal
    sides = box._sides()
    write_msh(tmp_path / "box.msh", m.points, m.tets, {"disk": faces, "base": sides["bottom"], "lid": sides["top"]},
              version)
    mine = get_problem("file_body")(mesh_file=str(tmp_path / "box.msh"), defects=[{"group": "disk"}],
                                    boundary=[{"group": "base", "support": "clamp"},
                                              {"group": "lid", "traction": [0.0, 1.0, 10.0]}])
    a, b = box.build(), mine.build()
    _same_qp(a, b)
    assert np.array_equal(a.interface.front, b.interface.front)


PLATE = """h = 0.1;
Point(1) = {0, 0, 0, h}; Point(2) = {1, 0, 0, h}; Point(3) = {1, 1, 0, h}; Point(4) = {0, 1, 0, h};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 1};
Curve Loop(1) = {1, 2, 3, 4}; Plane Surface(1) = {1};
Point(5) = {X0, 0.5, 0, h}; Point(6) = {0.6, 0.5, 0, h}; Line(5) = {5, 6};
EMBED
Physical Surface("body") = {1};
Physical Curve("base") = {1};
Physical Curve("lid") = {3};
Physical Curve("crack") = {5};
"""
SCENE = """geometry_file = "plate.geo"
mesh_size = 0.1
tip_size = 0.03
[[defects]]
group = "crack"
[[boundary]]
group = "base"
support = "clamp"
[[boundary]]
group = "lid"
traction = [0, 10]
"""


EDGE = """h = 0.1;
Point(1) = {0, 0, 0, h}; Point(2) = {1, 0, 0, h}; Point(3) = {1, 1, 0, h}; Point(4) = {0, 1, 0, h};
Point(5) = {0, 0.5, 0, h}; Point(6) = {0.6, 0.5, 0, h};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 5}; Line(6) = {5, 1};
Curve Loop(1) = {1, 2, 3, 4, 6}; Plane Surface(1) = {1};
Line(5) = {5, 6};
Line{5} In Surface{1};
Physical Surface("body") = {1};
Physical Curve("base") = {1};
Physical Curve("lid") = {3};
Physical Curve("crack") = {5};
"""


def _plate(tmp_path, x0=0.3, embed=True, scene=SCENE, extra="") -> Path:
    text = EDGE if x0 == 0 else PLATE.replace("X0", str(x0)).replace("EMBED", "Line{5} In Surface{1};" if embed else "")
    (tmp_path / "plate.geo").write_text(text + extra)
    (tmp_path / "plate.toml").write_text(scene)
    return tmp_path / "plate.toml"


def test_scene_file_picks_file_body_and_reads_relative_paths(tmp_path, monkeypatch):
    """A scene file with geometry_file is a file_body scene; its relative path is the scene file's folder's."""
    scene = _plate(tmp_path)
    monkeypatch.chdir("/")
    p = load_scene(str(scene))
    assert p.name == "file_body"
    qp = p.build()
    it = qp.interface
    assert it.m > 0 and it.front.size == 2                    # an interior crack: both tips single
    assert np.allclose(qp.geometry.nodes[:, it.front].T, [[0.3, 0.5], [0.6, 0.5]])
    assert np.allclose(it.normals, [0.0, 1.0])


def test_edge_crack_doubles_its_mouth(tmp_path):
    """A crack from the boundary (x = 0) to 0.6: its mouth node is doubled, only the inner tip stays single."""
    qp = load_scene(str(_plate(tmp_path, x0=0))).build()
    it = qp.interface
    nodes = qp.geometry.nodes
    assert it.front.size == 2 and np.allclose(nodes[:, it.front].T, [[0.0, 0.5], [0.6, 0.5]])
    assert it.front[0] in it.lower and it.front[1] not in it.lower      # the mouth doubled, the tip single
    mouth = int(np.argmin(nodes[0, it.lower]))
    assert np.allclose(nodes[:, it.lower[mouth]], [0.0, 0.5])  # the mouth is a doubled node
    last = np.linalg.norm(nodes[:, it.lower[np.argmax(nodes[0, it.lower])]] - [0.6, 0.5])
    assert np.isclose(it.weights.sum() + last / 2, 0.6)       # trapezoid weights: the mouth's half edge counts
    x = np.zeros(qp.n)
    assert qp.B.shape[0] == it.m and np.all(qp.B @ x == 0)


def _refused(tmp_path, match, **kw) -> None:
    with pytest.raises(InputError, match=match):
        load_scene(str(_plate(tmp_path, **kw))).build()


def test_unknown_group_lists_the_files_groups(tmp_path):
    _refused(tmp_path, r"'crak' is not a group of geometry_file 'plate.geo'; its groups: 'base' \(1D\), 'body' "
                       r"\(2D\), 'crack' \(1D\), 'lid' \(1D\)", scene=SCENE.replace('"crack"', '"crak"'))


def test_defect_not_embedded_is_refused(tmp_path):
    _refused(tmp_path, "is not embedded in the body", embed=False)


def test_mixed_element_types_are_refused(tmp_path):
    _refused(tmp_path, "unsupported element type", extra="Recombine Surface{1};\n")


def test_no_load_and_unbalanced_loads_are_refused(tmp_path):
    _refused(tmp_path, "needs its supports and loads", scene=SCENE.split("[[boundary]]")[0])
    free = SCENE.replace('support = "clamp"', 'traction = [0, 0]')
    _refused(tmp_path, "not in equilibrium", scene=free)


def test_missing_file_and_bad_keys(tmp_path):
    _refused(tmp_path, "does not exist", scene=SCENE.replace("plate.geo", "nothere.geo"))
    _refused(tmp_path, "give one of mesh_file", scene='mesh_file = "a.msh"\n' + SCENE)
    _refused(tmp_path, "unknown key 'points'", scene=SCENE.replace('group = "crack"', 'points = [[0, 0], [1, 1]]'))
    _refused(tmp_path, "no box sides", scene=SCENE.replace('group = "base"', 'side = "bottom"'))


def _square_msh(tmp_path, fold: bool = False, quad: bool = False) -> Path:
    """Two triangles of the unit square (a fold when asked), written with gmsh."""
    pts = np.array([[0.0, 1.0, 1.0, 0.0], [0.0, 0.0, 1.0, 1.0]])
    tri = np.array([[0, 1, 2], [0, 2, 3]]).T
    if fold:
        pts[:, 3] = [1.5, 0.4]                   # node 3 moved across the diagonal: triangle 1 folds over 0
    write_msh(tmp_path / "sq.msh", pts, tri, {"base": np.array([[0], [1]])})
    return tmp_path / "sq.msh"


def test_inverted_elements_and_too_large_files_are_refused(tmp_path, monkeypatch):
    path = _square_msh(tmp_path, fold=True)
    with pytest.raises(InputError, match="inverted element"):
        get_problem("file_body")(mesh_file=str(path), boundary=[{"group": "base", "support": "clamp"}])
    path = _square_msh(tmp_path)
    import dualfem.problems.file_body.read as rd

    monkeypatch.setattr(rd, "MAX_FILE_BYTES", 100)
    with pytest.raises(InputError, match="the largest mesh file read"):
        get_problem("file_body")(mesh_file=str(path), boundary=[{"group": "base", "support": "clamp"}])


EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "bodies"


def test_remote_stress_loads_the_outer_boundary_only():
    """Kirsch's plate: remote_stress pulls the plate's outer sides; the hole stays traction-free."""
    p = load_scene(str(EXAMPLES / "plate_hole.toml"))
    qp = p.build()
    c, _ = p.cut()
    F = p.nodal_load()
    hole = np.abs(np.hypot(*c.points) - 1.0) < 1e-9
    assert hole.sum() > 10 and np.abs(F[:, hole]).max() == 0.0
    right = np.abs(c.points[0] - 20.0) < 1e-9
    assert np.isclose(F[0, right].sum(), 40.0) and np.isclose(F[1].sum(), 0.0)
    assert qp.m == 0


def test_3d_body_from_a_geo_file():
    """The cylinder with an inclined penny (OpenCASCADE fragment): a 3D body, its crack doubled inside, its
    front single, normals along the disk's (the file's orientation)."""
    qp = load_scene(str(EXAMPLES / "cylinder_penny.toml")).build()
    it = qp.interface
    assert qp.geometry.dim == 3 and it.m > 10 and it.front.size > 10
    n0 = np.array([np.sin(np.pi / 6), 0.0, np.cos(np.pi / 6)])
    assert np.abs(np.abs(it.normals @ n0) - 1).max() < 1e-6
    r = np.linalg.norm(qp.geometry.nodes[:, it.front], axis=0)
    assert np.allclose(r, 1.0, atol=1e-6)


def test_sizes_are_bounded_before_meshing(tmp_path):
    _refused(tmp_path, r"gives about .* triangles \(limit", scene=SCENE.replace("mesh_size = 0.1", "mesh_size = 1e-5"))
    _refused(tmp_path, r"tip_size must be 0 or in \[0\.0001, 0\.1\]", scene=SCENE.replace("tip_size = 0.03",
                                                                                          "tip_size = 1e-7"))


def test_edge_crack_post_processing(tmp_path):
    """The defect fields of an edge crack: the mouth is a row of B (its jump the CMOD), the tip a single node."""
    from dualfem.post.fields import defect_fields
    from dualfem.runner import run

    qp = load_scene(str(_plate(tmp_path, x0=0))).build()
    sol = run("pdas", qp)
    d = defect_fields(qp, sol.x, sol.multipliers)
    assert d["row"][0] >= 0 and d["row"][-1] == -1 and d["s"][0] == 0.0
    assert d["jump_normal"][0] == pytest.approx((qp.B @ sol.x)[d["row"][0]]) and d["jump_normal"][-1] == 0.0


def test_face_pressure_opens_a_crack_and_delta_sweeps_reuse_the_assembly(tmp_path):
    """A pressurized crack in a plate clamped at its base (no other load) opens; a new delta reuses the mesh and
    the delta-free stiffness (one assembly)."""
    from dualfem.runner import run

    scene = SCENE.replace('group = "crack"', 'group = "crack"\nface_pressure = 5.0')
    scene = scene.split('[[boundary]]\ngroup = "lid"')[0]
    p = load_scene(str(_plate(tmp_path, scene=scene)))
    qp = p.build()
    F = p.nodal_load()
    assert np.allclose(F.sum(axis=1), 0.0, atol=1e-12) and np.abs(F).max() > 0
    sol = run("pdas", qp)
    assert (qp.B @ sol.x).min() > 0
    q = p.with_params(delta=1e-3)
    q.build()
    assert q.shared is p.shared and p.shared.assemblies == 1


def test_vtu_body_under_remote_stress_carries_it_uniformly(tmp_path):
    """A body in another format meshio reads (VTU, no groups), uncracked, under remote_stress alone: the stress is
    the remote stress in every triangle (rigid motions removed, no reactions)."""
    from dualfem.post.fields import stresses
    from dualfem.runner import run

    box = get_problem("thin_defect")(mesh="gmsh", mesh_size=0.2, defects=[], width=2.0,
                                     remote_stress=[[1.0, 0.5], [0.5, -2.0]])
    pts, tri, _ = box._reference_mesh()
    meshio.write(tmp_path / "body.vtu", meshio.Mesh(np.vstack([pts, np.zeros(pts.shape[1])]).T, [("triangle", tri.T)]))
    p = get_problem("file_body")(mesh_file=str(tmp_path / "body.vtu"), remote_stress=[[1.0, 0.5], [0.5, -2.0]])
    qp = p.build()
    s = stresses(qp, run("pdas", qp).x)
    for k, want in (("s11", 1.0), ("s22", -2.0), ("s12", 0.5)):
        assert np.allclose(s[k], want, atol=1e-9)


def _edge_strip(tmp_path, **extra):
    """The strip 1 x 6 with an edge crack of length 0.3 (examples/bodies/edge_crack.geo), tension on its ends."""
    src = Path(__file__).resolve().parent.parent / "examples" / "bodies" / "edge_crack.geo"
    geo = tmp_path / "edge.geo"
    geo.write_text(src.read_text().replace("H = 4;", "H = 6;"))
    return get_problem("file_body")(geometry_file=str(geo), mesh_size=0.1, tip_size=0.01, E=1000.0, nu=0.3,
                                    delta=1e3, defects=[{"group": "crack"}],
                                    boundary=[{"group": "top", "traction": [0.0, 1.0]},
                                              {"group": "bottom", "traction": [0.0, -1.0]}], **extra)


def test_geometry_file_body_refines_adaptively(tmp_path):
    """refine = "adaptive" re-meshes a geometry file by the estimate: the edge crack's K_I goes from 2.6 % under
    Tada's on the tip-graded start to within 1 %; the QP of a body without the keys keeps its parameters."""
    import math

    from dualfem.experiments.runner import run
    from dualfem.post.sif_outputs import stress_intensity

    c = math.pi * 0.3 / 2
    tada = math.sqrt(2 / (math.pi * 0.3) * math.tan(c)) * (0.752 + 0.606 + 0.37 * (1 - math.sin(c)) ** 3) \
        / math.cos(c) * math.sqrt(math.pi * 0.3)
    base = _edge_strip(tmp_path).build()
    assert "refine" not in base.params and "target_error" not in base.params
    qp = _edge_strip(tmp_path, refine="adaptive", target_error=1e-4, max_unknowns=5000).build()
    assert qp.params["adaptive_steps"] >= 2 and base.n < qp.n <= 5000
    k0, k1 = (stress_intensity(q, run("pdas", q).x).K_I[0] / tada - 1 for q in (base, qp))
    assert abs(k0) > 0.02 and abs(k1) < 0.01
    with pytest.raises(InputError, match="max_unknowns is a key of adaptive refinement"):
        _edge_strip(tmp_path, max_unknowns=7000)


def test_mesh_file_body_refuses_adaptive_refinement(tmp_path):
    from dualfem.experiments.adaptive import adapt

    path = _square_msh(tmp_path)
    with pytest.raises(InputError, match="needs geometry_file"):
        get_problem("file_body")(mesh_file=str(path), refine="adaptive")
    body = get_problem("file_body")(mesh_file=str(path), boundary=[{"group": "base", "support": "clamp"}])
    with pytest.raises(InputError, match="mesh_file body cannot be re-meshed"):
        next(adapt(body))
