"""gmsh meshes with embedded defects (problems/gmsh_mesh.py) and the scene library scenes/."""
from __future__ import annotations

import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from dualfem.core.errors import InputError, MissingDependency
from dualfem.problems.gmsh_mesh import (
    DefectMesh,
    estimate_triangles,
    mesh_with_defects,
    rotate,
    sample_defect,
)

gmsh = pytest.importorskip("gmsh")

SCENES = sorted(p for p in (Path(__file__).resolve().parents[1] / "scenes").glob("*.toml")
                if tomllib.loads(p.read_text(encoding="utf-8")).get("dim", 2) == 2)     # the 2D mesher's scenes
KINKED = [{"points": [[0.2, 0.3], [0.5, 0.45], [0.8, 0.45]], "curve": "polyline"}]
CURVED = [{"points": [[0.2, 0.45], [0.5, 0.6], [0.8, 0.45]], "curve": "spline"}]
TWO = [{"points": [[0.15, 0.35], [0.45, 0.4]], "curve": "polyline"},
       {"points": [[0.55, 0.65], [0.7, 0.6], [0.85, 0.62]], "curve": "spline"}]


def _scene(path: Path) -> dict:
    return tomllib.loads(path.read_text(encoding="utf-8"))


def _edges(tri: np.ndarray) -> np.ndarray:
    """All triangle edges (3 nt, 2), each sorted."""
    e = np.concatenate([tri[[0, 1]], tri[[1, 2]], tri[[2, 0]]], axis=1).T
    return np.sort(e, axis=1)


def _edge_count(tri: np.ndarray) -> dict[tuple[int, int], int]:
    e, c = np.unique(_edges(tri), axis=0, return_counts=True)
    return {tuple(map(int, k)): int(v) for k, v in zip(e, c, strict=True)}


def _signed_areas(m: DefectMesh) -> np.ndarray:
    p = m.points[:, m.triangles]
    return 0.5 * ((p[0, 1] - p[0, 0]) * (p[1, 2] - p[1, 0]) - (p[0, 2] - p[0, 0]) * (p[1, 1] - p[1, 0]))


def _dist_to_polyline(q: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Distance of points q (m, 2) to the polyline S (s, 2)."""
    a, b = S[:-1][None], S[1:][None]
    d = b - a
    t = np.clip(((q[:, None] - a) * d).sum(-1) / (d * d).sum(-1), 0, 1)
    return np.linalg.norm(q[:, None] - (a + t[..., None] * d), axis=-1).min(axis=1)


def _check_mesh(m: DefectMesh, defects: list[dict], width: float = 1.0, height: float = 1.0) -> None:
    n = m.points.shape[1]
    assert m.points.dtype == np.float64 and m.points.shape == (2, n)
    assert m.triangles.dtype == np.int64 and m.triangles.shape[0] == 3
    assert np.array_equal(np.unique(m.triangles), np.arange(n)), "every node is in a triangle"
    assert len(np.unique(m.points.round(12), axis=1).T) == n, "no duplicate nodes"
    areas = _signed_areas(m)
    assert areas.min() > 0, "counter-clockwise triangles with positive area"
    assert abs(areas.sum() - width * height) < 1e-12 * width * height
    count = _edge_count(m.triangles)
    assert set(count.values()) <= {1, 2}
    for d, nodes in zip(defects, m.defect_nodes, strict=True):
        P = np.asarray(d["points"], float)
        xy = m.points[:, nodes].T
        assert nodes.dtype == np.int64 and len(np.unique(nodes)) == len(nodes)
        for a, b in zip(nodes[:-1], nodes[1:], strict=True):   # conforming: interior edges of the mesh
            assert count.get((min(a, b), max(a, b))) == 2
        assert np.allclose(xy[0], P[0], atol=1e-14) and np.allclose(xy[-1], P[-1], atol=1e-14)
        if d["curve"] == "polyline":
            for pt in P:                              # kinks are nodes
                assert np.linalg.norm(xy - pt, axis=1).min() < 1e-14
            assert _dist_to_polyline(xy, P).max() < 1e-12
        else:
            assert _dist_to_polyline(xy, sample_defect(P, "spline", per_span=4096)).max() < 1e-7
    # boundary: nodes on their sides, ordered, corners included, and every boundary edge on a side
    coord = {"bottom": (1, 0.0), "top": (1, height), "left": (0, 0.0), "right": (0, width)}
    for side, (axis, value) in coord.items():
        b = m.boundary[side]
        assert np.allclose(m.points[axis, b], value, atol=1e-14)
        along = m.points[1 - axis, b]
        assert np.all(np.diff(along) > 0) and along[0] == 0 and along[-1] == (width if axis else height)
    on_boundary = {v for e, c in count.items() if c == 1 for v in e}
    assert on_boundary == set(np.concatenate(list(m.boundary.values())).tolist())


@pytest.mark.parametrize("defects", [KINKED, CURVED, TWO], ids=["kinked", "curved", "two"])
def test_mesh_conforms(defects):
    _check_mesh(mesh_with_defects(1.0, 1.0, defects, 0.05), defects)


def test_rectangle_with_tip_refinement_conforms():
    defects = [{"points": [[0.3, 0.2], [1.2, 0.5], [1.6, 0.3]], "curve": "spline"}]
    _check_mesh(mesh_with_defects(2.0, 0.8, defects, 0.08, tip_size=0.02), defects, 2.0, 0.8)


def test_sample_defect_is_gmsh_spline():
    """sample_defect evaluates exactly the curve gmsh builds with geo.addSpline."""
    P = np.array([[0.1, 0.2], [0.4, 0.7], [0.5, 0.3], [0.9, 0.6], [0.7, 0.9]])
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        tags = [gmsh.model.geo.addPoint(x, y, 0) for x, y in P]
        c = gmsh.model.geo.addSpline(tags)
        gmsh.model.geo.synchronize()
        u = np.linspace(0, 1, 4 * 16 + 1)
        ref = np.reshape(gmsh.model.getValue(1, c, u), (-1, 3))[:, :2]
    finally:
        gmsh.finalize()
    assert np.abs(sample_defect(P, "spline", per_span=16) - ref).max() < 1e-13
    assert np.array_equal(sample_defect(P, "polyline"), P)


def test_reproducible_and_silent(capfd):
    a = mesh_with_defects(1.0, 1.0, TWO, 0.04, tip_size=0.01)
    b = mesh_with_defects(1.0, 1.0, TWO, 0.04, tip_size=0.01)
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    assert np.array_equal(a.points, b.points) and np.array_equal(a.triangles, b.triangles)
    assert all(np.array_equal(x, y) for x, y in zip(a.defect_nodes, b.defect_nodes, strict=True))
    assert all(np.array_equal(a.boundary[s], b.boundary[s]) for s in a.boundary)


def test_caller_gmsh_session_is_left_alone():
    ref = mesh_with_defects(1.0, 1.0, KINKED, 0.05)
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("user_model")
        gmsh.option.setNumber("Mesh.Algorithm", 5)
        m = mesh_with_defects(1.0, 1.0, KINKED, 0.05)
        assert gmsh.isInitialized() and gmsh.model.getCurrent() == "user_model"
        assert gmsh.option.getNumber("Mesh.Algorithm") == 5
    finally:
        gmsh.finalize()
    assert np.array_equal(m.points, ref.points) and np.array_equal(m.triangles, ref.triangles)


def _edge_lengths_near(m: DefectMesh, pt, radius: float) -> np.ndarray:
    e = np.unique(_edges(m.triangles), axis=0)
    mid = 0.5 * (m.points[:, e[:, 0]] + m.points[:, e[:, 1]])
    near = np.linalg.norm(mid.T - np.asarray(pt), axis=1) < radius
    return np.linalg.norm(m.points[:, e[near, 0]] - m.points[:, e[near, 1]], axis=0)


def test_refinement_toward_tips():
    coarse = mesh_with_defects(1.0, 1.0, CURVED, 0.05)
    fine = mesh_with_defects(1.0, 1.0, CURVED, 0.05, tip_size=0.005)
    for tip in ([0.2, 0.45], [0.8, 0.45]):
        assert np.median(_edge_lengths_near(fine, tip, 0.01)) < 0.01
        assert np.median(_edge_lengths_near(coarse, tip, 0.05)) > 0.03
    far = [0.5, 0.15]   # away from the defect, both meshes keep the size about mesh_size
    assert 0.03 < np.median(_edge_lengths_near(fine, far, 0.08)) < 0.06
    assert fine.points.shape[1] > coarse.points.shape[1]


@pytest.mark.parametrize("tip_size", [None, 0.01])
def test_triangle_estimate_is_close(tip_size):
    m = mesh_with_defects(1.0, 1.0, KINKED, 0.04, tip_size=tip_size)
    est = estimate_triangles(1.0, 1.0, 0.04, tip_size, n_tips=2)
    assert 0.6 < est / m.triangles.shape[1] < 1.6


def test_rotate():
    p = np.array([[1.0, 0.5], [0.5, 0.5]])           # points (1, 0.5) and (0.5, 0.5) as columns
    q = rotate(p, 90, (0.5, 0.5))
    assert np.allclose(q, [[0.5, 0.5], [1.0, 0.5]])
    m = mesh_with_defects(1.0, 1.0, KINKED, 0.1)
    r = rotate(m.points, 33.0, (0.5, 0.5))
    assert np.allclose(rotate(r, -33.0, (0.5, 0.5)), m.points, atol=1e-14)
    rotated = DefectMesh(r, m.triangles, m.defect_nodes, m.boundary)
    assert np.allclose(_signed_areas(rotated), _signed_areas(m), rtol=1e-12)
    with pytest.raises(InputError, match="shape"):
        rotate(np.zeros((3, 2)), 10, (0, 0))


def _defs(*pts, curve="polyline"):
    return [{"points": p, "curve": curve} for p in pts]


BAD = [
    (_defs([[0.2, 0.2], [0.8, 0.8]], [[0.2, 0.8], [0.8, 0.2]]), r"defects\[0\] and defects\[1\] cross"),
    (_defs([[0.1, 0.1], [0.3, 0.1]], [[0.5, 0.5], [0.6, 0.6]], [[0.2, 0.9], [0.2, 0.05]]),
     r"defects\[0\] and defects\[2\] cross"),
    (_defs([[0.2, 0.5], [0.8, 0.5]], [[0.5, 0.5], [0.5, 0.8]]), r"defects\[0\] and defects\[1\] touch"),
    (_defs([[0.2, 0.5], [0.5, 0.5]], [[0.5, 0.5], [0.8, 0.7]]), r"defects\[0\] and defects\[1\] touch"),
    (_defs([[0.2, 0.5], [0.8, 0.5]], [[0.2, 0.5], [0.8, 0.5]]), r"defects\[0\] and defects\[1\] touch"),
    (_defs([[0.2, 0.5], [0.8, 0.5]]) + _defs([[0.3, 0.6], [0.5, 0.45], [0.7, 0.6]], curve="spline"),
     r"defects\[0\] and defects\[1\] cross"),
    (_defs([[0.2, 0.5], [1.2, 0.5]]), r"defects\[0\]: point \(1\.2, 0\.5\) is not strictly inside"),
    (_defs([[0.2, 0.5], [0.5, 0.5]], [[0.0, 0.3], [0.4, 0.3]]), r"defects\[1\]: point \(0, 0\.3\) is not strictly"),
    (_defs([[0.1, 0.5], [0.3, 0.97], [0.7, 0.97], [0.9, 0.5]], curve="spline"),
     r"defects\[0\]: curve point .* not strictly inside"),
    (_defs([[0.5, 0.5], [0.6, 0.6]], [[0.2, 0.2], [0.8, 0.8], [0.8, 0.2], [0.2, 0.8]]),
     r"defects\[1\] intersects itself"),
    (_defs([[0.2, 0.5], [0.6, 0.5], [0.4, 0.5]]), r"defects\[0\] intersects itself: it folds back"),
    (_defs([[0.2, 0.5], [0.8, 0.5], [0.8, 0.8], [0.5, 0.3]], curve="spline"), r"defects\[0\] intersects itself"),
    (_defs([[0.2, 0.5]]), r"defects\[0\]: points must be k >= 2 points"),
    (_defs([[0.2, 0.5], [0.3, 0.5]], [[0.4, 0.5], [0.4, 0.5]]), r"defects\[1\]: points 0 and 1 coincide"),
    (_defs([[0.2, 0.5], [0.6, 0.5], [0.2, 0.5]]), r"defects\[0\]: points 0 and 2 coincide"),
    (_defs([[0.2, float("nan")], [0.6, 0.5]]), r"defects\[0\]: points must be finite"),
    (_defs([[0.2, 0.5], [0.6, "a"]]), r"defects\[0\]: points must be a list"),
    ([{"points": [[0.2, 0.5], [0.6, 0.5]], "curve": "arc"}], r"defects\[0\]: curve must be"),
    ([{"curve": "spline"}], r"defects\[0\] must be a table with 'points'"),
    ("[[0.2, 0.5], [0.6, 0.5]]", r"defects must be a list"),
]


@pytest.mark.parametrize("defects, message", BAD)
def test_bad_defects_are_refused(defects, message):
    with pytest.raises(InputError, match=message):
        mesh_with_defects(1.0, 1.0, defects, 0.05)


@pytest.mark.parametrize("kwargs, message", [
    ({"mesh_size": 0}, "mesh_size must be a finite number > 0"),
    ({"mesh_size": -0.1}, "mesh_size must be a finite number > 0"),
    ({"mesh_size": float("nan")}, "mesh_size must be a finite number > 0"),
    ({"mesh_size": 0.6, "height": 0.5}, r"mesh_size must be in \(0, min\(width, height\)\] = \(0, 0.5\]"),
    ({"mesh_size": 1e-4}, r"gives about 230,9\d\d,\d\d\d triangles \(limit 5,000,000\)"),
    ({"mesh_size": 5e-4, "tip_size": 1e-4},
     r"mesh_size=0.0005 gives about 9,2\d\d,\d\d\d triangles .*mesh_size must be in \[0.00068, 1\]"),
    # the tips' refinement alone too fine: the allowed range of tip_size is named
    ({"tip_size": 1e-12}, r"mesh_size=0.05, tip_size=1e-12 gives about .* tip_size must be in \[1.2\de-09, 0.05\]"),
    # sizes that overflow a float estimate are refused, not a ZeroDivisionError
    ({"mesh_size": 1e-200}, r"mesh_size=1e-200 gives about 1e\+30 triangles .*mesh_size must be in"),
    ({"tip_size": 1e-300}, r"tip_size=1e-300 gives about .*tip_size must be in"),
    ({"tip_size": 0.0}, "tip_size must be a finite number > 0"),
    ({"width": -1.0}, "width must be a finite number > 0"),
])
def test_bad_sizes_are_refused(kwargs, message):
    args = {"width": 1.0, "height": 1.0, "defects": KINKED, "mesh_size": 0.05} | kwargs
    if "height" in kwargs:
        args["defects"] = _defs([[0.2, 0.2], [0.8, 0.3]])
    with pytest.raises(InputError, match=message):
        mesh_with_defects(**args)


def test_tip_size_above_mesh_size_follows_mesh_size():
    """A tip_size >= mesh_size (a default tip_size with a finer mesh_size) asks for nothing finer than the
    uniform mesh: the same mesh as no tip_size, not an error."""
    from dualfem.problems.gmsh_mesh import effective_tip_size

    assert effective_tip_size(0.004, 0.01) is None and effective_tip_size(0.05, 0.01) == 0.01
    plain = mesh_with_defects(1.0, 1.0, KINKED, 0.1)
    coarse_tip = mesh_with_defects(1.0, 1.0, KINKED, 0.1, tip_size=0.25)
    assert np.array_equal(plain.points, coarse_tip.points) and np.array_equal(plain.triangles, coarse_tip.triangles)


def test_missing_gmsh_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "gmsh", None)     # "import gmsh" now raises ImportError
    with pytest.raises(MissingDependency, match=r"pip install 'dualfem\[gmsh\]'"):
        mesh_with_defects(1.0, 1.0, KINKED, 0.05)


# ------------------------------------------------------------------------------ scenes/
def test_scene_library_is_complete():
    names = {p.stem for p in SCENES}
    assert {"inclined", "curved", "kinked", "two_defects", "near_boundary", "symmetric"} <= names


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_scene_meshes(path):
    sc = _scene(path)
    assert sc["mesh"] == "gmsh" and sc["defects"]
    W, H = sc.get("width", 1.0), sc.get("height", 1.0)
    m = mesh_with_defects(W, H, sc["defects"], sc["mesh_size"], sc.get("tip_size"))
    _check_mesh(m, sc["defects"], W, H)


def test_near_boundary_scene_is_near_but_inside():
    sc = _scene(next(p for p in SCENES if p.stem == "near_boundary"))
    P = np.concatenate([np.asarray(d["points"], float) for d in sc["defects"]])
    gap = np.minimum.reduce([P[:, 0], 1 - P[:, 0], P[:, 1], 1 - P[:, 1]]).min()
    assert 0 < gap < sc["mesh_size"]


def test_symmetric_scene_is_symmetric():
    from dualfem.problems.loads import resolve_load

    sc = _scene(next(p for p in SCENES if p.stem == "symmetric"))
    W = sc.get("width", 1.0)
    curves = [np.asarray(d["points"], float) for d in sc["defects"]]
    mirrored = [np.column_stack([W - c[::-1, 0], c[::-1, 1]]) for c in curves]
    key = sorted(c.round(12).tobytes() for c in curves)
    assert key == sorted(c.round(12).tobytes() for c in mirrored)
    g = resolve_load(sc["load"], W)
    x = np.linspace(0, W, 101)
    assert np.allclose(g(x, np.ones_like(x)), g(W - x, np.ones_like(x)), atol=1e-12)
    assert np.ptp(g(x, np.ones_like(x))) > 0, "not a uniform load: the contact set is not trivially all or nothing"


def _digest(m: DefectMesh) -> str:
    import hashlib

    h = hashlib.sha256(m.points.tobytes() + m.triangles.tobytes())
    for a in [*m.defect_nodes, *m.boundary.values()]:
        h.update(a.tobytes())
    return h.hexdigest()


def test_reproducible_across_processes():
    import os
    import subprocess

    code = ("import hashlib, sys; from dualfem.problems.gmsh_mesh import mesh_with_defects; "
            f"m = mesh_with_defects(1.0, 1.0, {TWO!r}, 0.04, tip_size=0.01); "
            "h = hashlib.sha256(m.points.tobytes() + m.triangles.tobytes()); "
            "[h.update(a.tobytes()) for a in [*m.defect_nodes, *m.boundary.values()]]; "
            "sys.stdout.write(h.hexdigest())")
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(root)})
    assert out.stdout == _digest(mesh_with_defects(1.0, 1.0, TWO, 0.04, tip_size=0.01))


# ------------------------------------------------------------------- mirror-symmetric meshes
SYM = [{"points": [[0.1, 0.3], [0.3, 0.35], [0.4, 0.3]], "curve": "spline"},
       {"points": [[0.9, 0.3], [0.7, 0.35], [0.6, 0.3]], "curve": "spline"},       # mirror image of 0
       {"points": [[0.2, 0.7], [0.4, 0.6], [0.6, 0.6], [0.8, 0.7]], "curve": "polyline"},   # crosses the axis
       {"points": [[0.3, 0.85], [0.5, 0.8], [0.7, 0.85]], "curve": "polyline"}]    # kink on the axis


def test_symmetric_mesh_is_a_mirror_image():
    from dualfem.problems.gmsh_symmetric import mesh_symmetric

    m = mesh_symmetric(1.0, 1.0, SYM, 0.05, tip_size=0.0125)
    _check_mesh(m, SYM)
    mi = m.mirror
    assert np.array_equal(mi[mi], np.arange(len(mi)))
    assert np.abs(m.points[0, mi] - (1.0 - m.points[0])).max() < 1e-15
    assert np.array_equal(m.points[1, mi], m.points[1])
    tris = {tuple(sorted(t)) for t in m.triangles.T.tolist()}
    assert tris == {tuple(sorted(t)) for t in mi[m.triangles].T.tolist()}
    for k in (2, 3):     # self-symmetric defects: the node list reversed is its own mirror image
        assert np.array_equal(mi[m.defect_nodes[k][::-1]], m.defect_nodes[k])
    assert np.array_equal(mi[m.defect_nodes[0]], m.defect_nodes[1])    # both run from their outer tip
    assert np.array_equal(mi[m.boundary["left"]], m.boundary["right"])
    assert np.array_equal(mi[m.boundary["bottom"][::-1]], m.boundary["bottom"])
    again = mesh_symmetric(1.0, 1.0, SYM, 0.05, tip_size=0.0125)
    assert np.array_equal(again.points, m.points) and np.array_equal(again.triangles, m.triangles)


def test_symmetric_mesh_pairs_in_any_order_and_direction():
    from dualfem.problems.gmsh_symmetric import mesh_symmetric

    defects = [{"points": SYM[1]["points"][::-1], "curve": "spline"}, SYM[0]]   # right one first, reversed
    m = mesh_symmetric(1.0, 1.0, defects, 0.05)
    _check_mesh(m, defects)      # each node list runs from the defect's first point to its last
    assert np.array_equal(m.mirror[m.defect_nodes[1][::-1]], m.defect_nodes[0])


def test_symmetric_scene_meshes_symmetrically():
    from dualfem.problems.gmsh_symmetric import mesh_symmetric

    sc = _scene(next(p for p in SCENES if p.stem == "symmetric"))
    m = mesh_symmetric(1.0, 1.0, sc["defects"], sc["mesh_size"], sc.get("tip_size"))
    _check_mesh(m, sc["defects"])
    assert np.array_equal(m.mirror[m.defect_nodes[0][::-1]], m.defect_nodes[0])


@pytest.mark.parametrize("defects, message", [
    (_defs([[0.2, 0.5], [0.4, 0.5]]), r"defects\[0\] has no mirror image about x = 0.5"),
    (_defs([[0.2, 0.5], [0.4, 0.5]], [[0.6, 0.5], [0.8, 0.55]]), r"defects\[0\] has no mirror image"),
    (_defs([[0.3, 0.5], [0.5, 0.6], [0.7, 0.5]], curve="spline"), r"defects\[0\] is a spline crossing the symmetry"),
    (_defs([[0.2, 0.2], [0.8, 0.8]], [[0.2, 0.8], [0.8, 0.2]]), r"defects\[0\] and defects\[1\] cross"),
])
def test_symmetric_mesh_refuses_asymmetric_defects(defects, message):
    from dualfem.problems.gmsh_symmetric import mesh_symmetric

    with pytest.raises(InputError, match=message):
        mesh_symmetric(1.0, 1.0, defects, 0.05)
