"""Fracture networks of any size (issue 35, items 2 and 4): the size guard instead of a count cap, near-linear
pair checks, ``defects_file`` (CSV/JSON, 2D and 3D) and its round trip from ``random_cracks``, the load-model
trap, ``size_growth``, and the uncracked body under a remote stress."""
from __future__ import annotations

import json

import numpy as np
import pytest

from dualfem.errors import InputError
from dualfem.problems import gmsh_mesh
from dualfem.problems.defects_file import read_defects, write_defects
from dualfem.problems.fractured import random_cracks
from dualfem.problems.three_d.geometry import check_apart, parse_surface
from dualfem.scene import load_scene

gmsh = pytest.importorskip("gmsh")


def _same_qp(a, b) -> None:
    assert a.K.shape == b.K.shape and abs(a.K - b.K).max() == 0
    assert np.array_equal(a.F, b.F) and abs(a.B - b.B).max() == 0 and np.array_equal(a.weights, b.weights)


# ------------------------------------------------------------------ many defects: the guard, fast checks
def test_two_thousand_cracks_validate_and_a_touching_pair_is_found():
    cracks = random_cracks(cracks=2000, crack_length=0.01, min_gap=0.004, seed=3)
    assert len(gmsh_mesh.validate(1.0, 1.0, cracks, 0.02, 0.002)) == 2000
    bad = [dict(c) for c in cracks]
    p0, p1 = np.asarray(bad[1500]["points"])
    mid = 0.5 * (p0 + p1)
    bad[1700] = {"points": [(mid - [0.001, 0.001]).tolist(), (mid + [0.001, -0.001]).tolist()]}
    with pytest.raises(InputError, match=r"defects\[1500\] and defects\[1700\] (cross|touch)"):
        gmsh_mesh.validate(1.0, 1.0, bad, 0.02, 0.002)


def test_more_than_64_defects_make_a_scene_and_too_many_are_refused_by_size():
    many = [{"points": [[0.05 + 0.9 * i / 80, 0.3], [0.05 + 0.9 * i / 80, 0.7]]} for i in range(81)]
    qp = load_scene("f2", {"mesh": "gmsh", "mesh_size": 0.02, "defects": many}).build()
    assert len(np.unique(qp.interface.defect_id)) == 81
    with pytest.raises(InputError, match=r"with 81 defects \(162 tips"):
        load_scene("f2", {"mesh": "gmsh", "mesh_size": 0.02, "tip_size": 1e-9, "defects": many})


def test_a_self_intersecting_long_polyline_is_found_on_the_grid():
    t = np.linspace(0, 4 * np.pi, 3000)
    spiral = np.c_[0.5 + 0.3 * np.cos(t) * t / 13, 0.5 + 0.3 * np.sin(t) * t / 13]
    gmsh_mesh.validate(1.0, 1.0, [{"points": spiral[1:].tolist()}], 0.05)
    crossed = np.vstack([spiral[1:], [[0.5, 0.9], [0.5, 0.1]]])
    with pytest.raises(InputError, match=r"defects\[0\] intersects itself near"):
        gmsh_mesh.validate(1.0, 1.0, [{"points": crossed.tolist()}], 0.05)


def _brute_apart(surfaces, gap):
    """The check of every pair (the code before the prefilter), the first failing pair or None."""
    from scipy.spatial import cKDTree

    spacing = max(0.5 * gap, max(s.size() for s in surfaces) / 64)
    limit = max(gap, 2 * spacing)
    clouds = [s.sample(spacing) for s in surfaces]
    for i in range(len(surfaces)):
        for j in range(i + 1, len(surfaces)):
            if cKDTree(clouds[i]).query(clouds[j])[0].min() < limit:
                return i, j
    return None


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_3d_pair_check_agrees_with_every_pair(seed):
    rng = np.random.default_rng(seed)
    tables = [{"shape": "disk", "center": (rng.random(3) * 8 + 1).tolist(), "normal": rng.normal(size=3).tolist(),
               "radius": float(0.3 + 0.4 * rng.random())} for _ in range(60)]
    tables += [{"shape": "ellipse", "center": (rng.random(3) * 8 + 1).tolist(), "normal": [0, 0, 1],
                "axes": [0.6, 0.3], "direction": [1, 0, 0]} for _ in range(10)]
    surfaces = [parse_surface(i, t, 1e-5) for i, t in enumerate(tables)]
    first = _brute_apart(surfaces, 0.1)
    if first is None:
        check_apart(surfaces, 0.1)
    else:
        with pytest.raises(InputError, match=rf"defects\[{first[0]}\] and defects\[{first[1]}\] intersect"):
            check_apart(surfaces, 0.1)


def test_3d_scene_takes_more_than_32_disks():
    tables = [{"shape": "disk", "center": [1.5 + 2 * (i % 4), 1.5 + 2 * (i // 4 % 4), 2.0 + 3 * (i // 16)],
               "normal": [0, 0, 1], "radius": 0.4} for i in range(48)]
    pr = load_scene("penny", {"defects": tables, "mesh_size": 1.0, "tip_size": 1.0})
    assert len(pr._surfaces) == 48


# ------------------------------------------------------------------ defects_file
def test_csv_segments_polylines_and_json_read_as_tables(tmp_path):
    (tmp_path / "s.csv").write_text("x1,y1,x2,y2,delta\n0.1,0.2,0.3,0.2,\n0.5,0.5,0.6,0.7,1e-6\n")
    assert read_defects(tmp_path / "s.csv", 2) == [
        {"points": [[0.1, 0.2], [0.3, 0.2]], "curve": "polyline"},
        {"points": [[0.5, 0.5], [0.6, 0.7]], "curve": "polyline", "delta": 1e-6}]
    (tmp_path / "p.csv").write_text("defect,x,y\n7,0.1,0.1\n7,0.2,0.15\n7,0.3,0.1\n2,0.5,0.5\n2,0.6,0.5\n")
    got = read_defects(tmp_path / "p.csv", 2)
    assert [len(t["points"]) for t in got] == [3, 2] and got[0]["points"][1] == [0.2, 0.15]
    (tmp_path / "d.json").write_text(json.dumps([{"points": [[0.1, 0.1], [0.2, 0.2]], "curve": "spline"}]))
    assert read_defects(tmp_path / "d.json", 2)[0]["curve"] == "spline"


def test_3d_csv_mixes_disks_and_ellipses(tmp_path):
    f = tmp_path / "n.csv"
    f.write_text("cx,cy,cz,nx,ny,nz,radius,a,b,dx,dy,dz,delta\n"
                 "5,5,3,0,0,1,1.5,,,,,,\n"
                 "5,5,7,0,1,1,,2,1,1,0,0,1e-4\n")
    disk, ell = read_defects(f, 3)
    assert disk == {"shape": "disk", "center": [5.0, 5.0, 3.0], "normal": [0.0, 0.0, 1.0], "radius": 1.5}
    assert ell["shape"] == "ellipse" and ell["axes"] == [2.0, 1.0] and ell["direction"] == [1.0, 0.0, 0.0] \
        and ell["delta"] == 1e-4
    write_defects(tmp_path / "back.csv", [disk, ell], 3)
    assert read_defects(tmp_path / "back.csv", 3) == [disk, ell]
    box = {"width": 10.0, "depth": 10.0, "height": 10.0}
    qp = load_scene("three_d", {**box, "defects_file": str(f), "mesh_size": 2.5, "tip_size": 2.5}).build()
    assert set(np.unique(qp.interface.defect_id)) == {0, 1}


@pytest.mark.parametrize("text, dim, match", [
    ("x1,y1,x2\n0.1,0.2,0.3\n", 2, r"n\.csv', row 1: the header must be x1,y1,x2,y2\[,delta\] or defect,x,y"),
    ("x1,y1,x2,y2\n0.1,0.2,abc,0.4\n", 2, r"n\.csv', row 2, column 'x2': 'abc' is not a number"),
    ("x1,y1,x2,y2\n0.1,0.2,0.3,0.4\n0.1,nan,0.3,0.4\n", 2, r"row 3, column 'y1': 'nan' is not a finite number"),
    ("x1,y1,x2,y2\n0.1,0.2,0.3\n", 2, r"row 2: 3 values for the 4 columns"),
    ("defect,x,y\n1,0.1,0.1\n2,0.2,0.2\n1,0.3,0.3\n", 2, r"row 4, column 'defect': the rows of defect '1' must be "
                                                        r"consecutive"),
    ("defect,x,y\n1,0.1,0.1\n", 2, r"row 2: defect '1' has one point"),
    ("defect,x,y,delta\n1,0.1,0.1,1e-5\n1,0.2,0.2,1e-6\n", 2, r"row 3, column 'delta': defect '1' has another delta"),
    ("cx,cy,cz,nx,ny,nz,radius,a,b,dx,dy,dz\n1,1,1,0,0,1,0.5,1,,,,\n", 3, r"row 2: both radius and a"),
    ("cx,cy,cz,nx,ny,nz,radius\n", 3, r"holds no defect"),
    ("x1,y1,x2,y2\n0.1,0.2,0.3,0.4\n", 3, r"the header must be cx,cy,cz,nx,ny,nz,radius\[,delta\]"),
])
def test_bad_defects_files_name_the_row_and_column(tmp_path, text, dim, match):
    (tmp_path / "n.csv").write_text(text)
    with pytest.raises(InputError, match=match):
        read_defects(tmp_path / "n.csv", dim)


def test_file_size_is_checked_before_reading(tmp_path, monkeypatch):
    import dualfem.problems.defects_file as df

    f = tmp_path / "big.csv"
    f.write_text("x1,y1,x2,y2\n" + "0.1,0.2,0.3,0.4\n" * 100)
    monkeypatch.setattr(df, "MAX_BYTES", 1000)
    with pytest.raises(InputError, match=r"defects_file '.*big\.csv' has 1,612 bytes; the limit is 1,000"):
        read_defects(f, 2)
    with pytest.raises(InputError, match=r"must be a \.csv or \.json file"):
        read_defects(tmp_path / "net.txt", 2)


def test_scene_file_path_is_relative_to_the_scene(tmp_path, monkeypatch):
    sub = tmp_path / "case"
    sub.mkdir()
    (sub / "net.csv").write_text("x1,y1,x2,y2\n0.25,0.5,0.75,0.5\n")
    (sub / "scene.toml").write_text('mesh = "gmsh"\nmesh_size = 0.1\ndefects_file = "net.csv"\n')
    monkeypatch.chdir(tmp_path)
    a = load_scene(str(sub / "scene.toml")).build()
    b = load_scene("f2", {"mesh": "gmsh", "mesh_size": 0.1, "defects": [{"points": [[0.25, 0.5], [0.75, 0.5]]}]})
    _same_qp(a, b.build())
    assert a.params["defects_file"] == str(sub / "net.csv")
    with pytest.raises(InputError, match=r"give either \[\[defects\]\] tables or defects_file"):
        load_scene(str(sub / "scene.toml"), {"defects": []})
    (sub / "net.csv").write_text("x1,y1,x2,y2\n0.25,0.5,0.75,0.5\n0.5,0.2,0.5,1.2\n")
    with pytest.raises(InputError, match=r"defects_file '.*net\.csv': defects\[1\]\.points must lie strictly inside"):
        load_scene(str(sub / "scene.toml"))


def test_random_cracks_round_trip_to_the_same_qp(tmp_path):
    """The generator's cracks written as a CSV file and read back by a scene give the QP of the generated scene."""
    keys = {"cracks": 30, "seed": 4, "mesh_size": 0.04, "tip_size": 0.04}
    gen = load_scene("fractured", keys)
    path = write_defects(tmp_path / "net.csv", random_cracks(cracks=30, min_gap=0.08, seed=4), 2)
    assert np.array_equal(np.asarray([t["points"] for t in read_defects(path, 2)]), gen.crack_points)
    back = load_scene("fractured", {"defects_file": str(path), "mesh_size": 0.04, "tip_size": 0.04})
    _same_qp(gen.build(), back.build())
    with pytest.raises(InputError, match=r"defects_file gives the cracks; the generator's key 'seed' does not apply"):
        load_scene("fractured", {"defects_file": str(path), "seed": 3})
    write_defects(tmp_path / "net.json", random_cracks(cracks=30, min_gap=0.08, seed=4), 2)
    inline = load_scene("f2", {"mesh": "gmsh", "mesh_size": 0.01, "defects": random_cracks(30, min_gap=0.08, seed=4)})
    _same_qp(inline.build(), load_scene("f2", {"mesh": "gmsh", "mesh_size": 0.01,
                                               "defects_file": str(tmp_path / "net.json")}).build())


def test_a_units_study_refuses_a_defects_file():
    from dualfem.problems.thin_defect import ThinDefect

    with pytest.raises(InputError, match=r"defects_file = 'n\.csv' holds lengths in a file"):
        ThinDefect.unit_map.convert(ThinDefect.defaults, {"defects_file": "n.csv"}, 2.0, 3.0)


# ------------------------------------------------------------------ the small traps
@pytest.mark.parametrize("dim", [2, 3])
def test_uncracked_body_under_remote_stress_is_uniform_with_zero_reactions(dim):
    """``defects = []``: no constraint; under a remote stress S the displacement is affine (the stress S in
    every element) and the forces at the rigid-body removal vanish."""
    from dualfem.core.elasticity import lame

    S = np.array([[3.0, 1.0, 0.5], [1.0, -2.0, 0.2], [0.5, 0.2, 1.0]])[:dim, :dim]
    scene = ("f2", {"mesh": "gmsh", "mesh_size": 0.2}) if dim == 2 else ("three_d", {"mesh_size": 0.4})
    pr = load_scene(scene[0], {**scene[1], "defects": [], "remote_stress": S.tolist()})
    qp = pr.build()
    assert qp.B.shape[0] == 0
    x = np.linalg.solve(qp.K.toarray(), qp.F)
    g = qp.geometry
    u = np.zeros(g.node_dofs.shape)
    u[g.node_dofs >= 0] = x[g.node_dofs[g.node_dofs >= 0]]
    X = np.vstack([g.nodes, np.ones(g.nodes.shape[1])]).T              # u = G X + c, fitted
    coef, *_ = np.linalg.lstsq(X, u.T, rcond=None)
    assert np.abs(X @ coef - u.T).max() <= 1e-9 * np.abs(u).max()
    G = coef[:dim].T
    eps = 0.5 * (G + G.T)
    lam, mu = lame(qp.material.E, qp.material.nu, qp.material.plane)
    assert np.abs(lam * np.trace(eps) * np.eye(dim) + 2 * mu * eps - S).max() <= 1e-9 * np.abs(S).max()
    K_all = pr.assemble()[0] if dim == 2 else None
    if K_all is not None:                        # the reactions at the fixed components of the removal
        F_all = pr.assemble()[1]
        assert np.abs(K_all @ u.T.ravel() - F_all).max() <= 1e-9 * np.abs(F_all).max()


def test_face_pressure_alone_needs_a_load_model(tmp_path):
    scene = tmp_path / "p.toml"
    scene.write_text('[[defects]]\npoints = [[0.25, 0.5], [0.75, 0.5]]\nface_pressure = 2.0\n')
    with pytest.raises(InputError, match=r"defects\[0\]\.face_pressure is a load of the defects, and the scene "
                                         r"names no load model.*load = 'f2'"):
        load_scene(str(scene))
    assert load_scene(str(scene), {"load": "f2"})._loads is None          # the legacy model, asked for
    load_scene(str(scene), {"boundary": [{"side": "bottom", "support": "clamp"}]})
    load_scene(str(scene), {"defects": [{"points": [[0.25, 0.5], [0.75, 0.5]]}]})       # no defect load: legacy
    d = [{"points": [[0.25, 0.5], [0.75, 0.5]], "face_pressure": 2.0}]
    load_scene("f2", {"defects": d})                    # the f2 scene names its load
    with pytest.raises(InputError, match=r"face_pressure is a load of the defects.*load = 'f1'"):
        load_scene("fractured", {"cracks": 3, "face_pressure": 1.0})
    with pytest.raises(InputError, match=r"defects\[0\]\.face_pressure is a load of the defects.*load = 'f2'"):
        load_scene("three_d", {"defects": [{"shape": "disk", "center": [0.5, 0.5, 0.5], "normal": [0, 0, 1],
                                            "radius": 0.2, "face_pressure": 1.0}]})


@pytest.mark.parametrize("value", [0.0, 1.5, 0.005, -0.3])
def test_size_growth_is_validated(value):
    with pytest.raises(InputError, match=r"size_growth must be a number in \[0.01, 1\]"):
        load_scene("f2", {"mesh": "gmsh", "size_growth": value})
    with pytest.raises(InputError, match=r"size_growth must be a number in \[0.01, 1\]"):
        load_scene("three_d", {"size_growth": value})


def test_size_growth_refines_away_from_the_tips():
    keys = {"mesh": "gmsh", "mesh_size": 0.1, "tip_size": 0.005}
    steep, gentle = (load_scene("f2", {**keys, "size_growth": g}).build() for g in (0.3, 0.1))
    assert gentle.K.shape[0] > 2 * steep.K.shape[0]
    assert "size_growth" not in steep.params and gentle.params["size_growth"] == 0.1
    d3 = [load_scene("three_d", {"mesh_size": 0.25, "tip_size": 0.08, "size_growth": g}).build() for g in (0.3, 0.1)]
    assert d3[1].K.shape[0] > 1.3 * d3[0].K.shape[0]
