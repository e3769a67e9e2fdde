"""reports/bodies.md in one command: bodies from mesh and geometry files (problems/file_body) validated.

    python benchmarks/bodies.py --report reports            # every case (a few minutes on 2 cores)
    python benchmarks/bodies.py --report reports --quick    # the coarse levels only (a check of the script)
    python benchmarks/bodies.py --report reports --render-only

Cases, each solved by ``pdas`` through dualfem's runner (every answer certified by the evaluator):

1. round trip: a 2D ``thin_defect`` gmsh scene (two cracks, one kinked) and a 3D ``three_d`` scene (an inclined
   disk) written as MSH 2.2 and 4.1 (``write_msh``, through gmsh) and read back as ``mesh_file`` scenes with the
   same groups: the largest differences of K, F, B (relative to their largest entries);
2. Kirsch: a square plate of side 40 a with a hole of radius a = 1 (``examples/bodies/plate_hole.geo`` with the
   hole's element size per level), uncracked, ``remote_stress`` sigma_xx = 1: the hoop stress at the hole's edge
   at theta = 90 and 270 degrees, recovered by a least-squares fit of the element stresses near that point
   (sigma_tt = c0 + c1 d + c2 d^2 + c3 s^2, d the distance from the edge, s the arc length from the point,
   elements whose centroid lies within 4 h of it) and c0 taken; beside it the plain nodal average;
3. an edge crack (``examples/bodies/edge_crack.geo``): a strip of width b = 1, height 6, crack of length a from
   its left side at mid-height, tension sigma = 1 on its ends (no supports): the crack-mouth opening against
   Tada, Paris & Irwin, The Stress Analysis of Cracks Handbook (3rd ed., 2000), single edge notched strip in
   tension: CMOD = 4 sigma a V1(a/b) / E', V1 = [1.46 + 3.42 (1 - cos(pi a / 2b))] / cos^2(pi a / 2b) (stated
   accurate to 1 % for any a/b), E' = E / (1 - nu^2) (plane strain);
4. a cylinder (radius 5, height 10) with a penny of radius a = 1 tilted by 30 degrees
   (``examples/bodies/cylinder_penny.geo``) against the ``three_d`` box of side 10 with the same disk, both under
   sigma_zz = 1 on their ends: the opening over r <= 0.8 a against Sneddon's w = 8 (1 - nu^2) sigma_n / (pi E)
   sqrt(a^2 - r^2), sigma_n = sigma cos^2(30 deg), and against each other;
5. pictures: the edge-cracked strip's mesh with its groups and its von Mises stress on the deformed body; the
   Kirsch plate near the hole; the cylinder's section through the penny and the penny's opening and slip.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "2")
os.environ.setdefault("MKL_NUM_THREADS", "2")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE.parent / "examples" / "bodies"
E, NU = 1000.0, 0.3


def _solve(problem):
    from dualfem.experiments.runner import run
    from dualfem.scene import build_qp

    t = time.perf_counter()
    qp = build_qp(problem)
    t_build = time.perf_counter() - t
    sol = run("pdas", qp)
    if sol.status.value != "solved":
        raise RuntimeError(f"{qp.name}: pdas {sol.status.value}: {sol.message}")
    return qp, sol, t_build, time.perf_counter() - t


def _file_body(**params):
    from dualfem.registry import get_problem

    return get_problem("file_body")(**params)


# --------------------------------------------------------------------------- 1. round trip
def round_trip(tmp: Path, quick: bool) -> list[dict]:
    from dualfem.problems.three_d.mesh import mesh_box
    from dualfem.registry import get_problem

    rows = []
    h = 0.04 if quick else 0.01
    bnd = [{"side": "bottom", "support": "clamp"}, {"side": "top", "traction": [1.0, 10.0]}]
    defects = [{"points": [[0.3, 0.5], [0.7, 0.55]]}, {"points": [[0.2, 0.2], [0.4, 0.3], [0.5, 0.2]]}]
    box = get_problem("thin_defect")(mesh="gmsh", mesh_size=h, tip_size=h / 4, defects=defects, boundary=bnd)
    pts, tri, dn = box._reference_mesh()
    sides = box._box_sides()
    groups = {f"crack{k}": np.vstack([d[:-1], d[1:]]) for k, d in enumerate(dn)}
    groups |= {"base": sides["bottom"], "lid": sides["top"]}
    file_bnd = [{"group": "base", "support": "clamp"}, {"group": "lid", "traction": [1.0, 10.0]}]
    rows += _compare(box, tmp, pts, tri, groups, [{"group": "crack0"}, {"group": "crack1"}], file_bnd, "2D")
    bnd3 = [{"side": "bottom", "support": "clamp"}, {"side": "top", "traction": [0.0, 1.0, 10.0]}]
    disk = {"shape": "disk", "center": [0.5, 0.5, 0.5], "normal": [0.3, 0.0, 1.0], "radius": 0.25}
    box3 = get_problem("three_d")(mesh_size=0.25 if quick else 0.1, tip_size=0.1 if quick else 0.03, defects=[disk],
                                  boundary=bnd3)
    m = mesh_box(box3.box, box3._surfaces, box3.mesh_size, box3.tip_size, box3.surface_size)
    faces = m.faces[0].copy()
    P = m.points[:, faces]
    cr = np.cross((P[:, 1] - P[:, 0]).T, (P[:, 2] - P[:, 0]).T)
    flip = (cr * box3._surfaces[0].normal_at(P.mean(axis=1).T)).sum(axis=1) < 0
    faces[[0, 1]] = np.where(flip, faces[[1, 0]], faces[[0, 1]])
    s3 = box3._sides()
    file_bnd3 = [{"group": "base", "support": "clamp"}, {"group": "lid", "traction": [0.0, 1.0, 10.0]}]
    rows += _compare(box3, tmp, m.points, m.tets, {"disk": faces, "base": s3["bottom"], "lid": s3["top"]},
                     [{"group": "disk"}], file_bnd3, "3D")
    return rows


def _compare(box, tmp, pts, cells, groups, defects, bnd, label) -> list[dict]:
    from dualfem.problems.file_body.write import write_msh

    a = box.build()
    out = []
    for version in (2.2, 4.1):
        path = tmp / f"{label}_{version}.msh"
        write_msh(path, pts, cells, groups, version)
        b = _file_body(mesh_file=str(path), defects=defects, boundary=bnd).build()
        same_shape = a.K.shape == b.K.shape and a.B.shape == b.B.shape
        out.append({"case": f"{box.name} ({label})", "msh": version, "n": a.n, "m": a.m,
                    "size_MB": path.stat().st_size / 1e6, "same_shape": same_shape,
                    "K": float(abs(a.K - b.K).max() / abs(a.K).max()),
                    "F": float(np.abs(a.F - b.F).max() / np.abs(a.F).max()),
                    "B": float(abs(a.B - b.B).max() / abs(a.B).max())})
    return out


# --------------------------------------------------------------------------- 2. Kirsch
def kirsch(tmp: Path, quick: bool) -> list[dict]:
    rows = []
    levels = (0.2, 0.1) if quick else (0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625)
    text = (EXAMPLES / "plate_hole.geo").read_text()
    for h in levels:
        geo = tmp / f"kirsch_{h}.geo"
        geo.write_text(text.replace("h_hole = 0.1;", f"h_hole = {h};"))
        p = _file_body(geometry_file=str(geo), E=E, nu=NU, defects=[], remote_stress=[[1.0, 0.0], [0.0, 0.0]])
        qp, sol, t_build, t_all = _solve(p)
        fit, avg = [], []
        for theta in (math.pi / 2, 3 * math.pi / 2):
            f, a = _hoop(qp, sol.x, theta, h)
            fit.append(f)
            avg.append(a)
        rows.append({"h_hole": h, "n": qp.n, "hoop_fit": float(np.mean(fit)), "hoop_avg": float(np.mean(avg)),
                     "fit_90": fit[0], "fit_270": fit[1], "time_s": t_all})
    return rows


def _element_stress(qp, x):
    from dualfem.post.fields import stresses

    s = stresses(qp, x)
    return s["s11"], s["s22"], s["s12"]


def _hoop(qp, x, theta: float, h: float, a: float = 1.0) -> tuple[float, float]:
    """(sigma_tt at the hole's edge at angle theta by the least-squares fit, its nodal average there)."""
    nodes, tri = qp.geometry.nodes, qp.geometry.cells
    s11, s22, s12 = _element_stress(qp, x)
    cen = nodes[:, tri].mean(axis=1)
    r = np.hypot(*cen)
    th = np.arctan2(cen[1], cen[0])
    t1, t2 = -np.sin(th), np.cos(th)
    stt = s11 * t1 ** 2 + 2 * s12 * t1 * t2 + s22 * t2 ** 2
    point = a * np.array([math.cos(theta), math.sin(theta)])
    d = r - a
    arc = a * np.angle(np.exp(1j * (th - theta)))
    near = np.hypot(cen[0] - point[0], cen[1] - point[1]) <= 4 * h
    A = np.column_stack([np.ones(near.sum()), d[near], d[near] ** 2, arc[near] ** 2])
    coef = np.linalg.lstsq(A, stt[near], rcond=None)[0]
    k = int(np.argmin(np.hypot(nodes[0] - point[0], nodes[1] - point[1])))
    at = np.any(tri == k, axis=0)
    from dualfem.problems.file_body.body import signed_measure

    w = np.abs(signed_measure(nodes, tri[:, at]))
    return float(coef[0]), float((stt[at] * w).sum() / w.sum())


# --------------------------------------------------------------------------- 3. Tada
def tada_v1(s: float) -> float:
    c = math.cos(math.pi * s / 2)
    return (1.46 + 3.42 * (1 - c)) / c ** 2


def edge_crack(tmp: Path, quick: bool) -> list[dict]:
    rows = []
    text = (EXAMPLES / "edge_crack.geo").read_text().replace("H = 4;", "H = 6;")
    ratios = (0.3,) if quick else (0.1, 0.3, 0.5)
    levels = ((0.1, 0.01),) if quick else ((0.1, 0.01), (0.05, 0.004), (0.03, 0.0015))
    for s in ratios:
        geo = tmp / f"edge_{s}.geo"
        geo.write_text(text.replace("a = 0.3;", f"a = {s};"))
        exact = 4 * s * tada_v1(s) * (1 - NU ** 2) / E
        for hs, tip in levels:
            p = _file_body(geometry_file=str(geo), mesh_size=hs, tip_size=tip, E=E, nu=NU, delta=1e3,
                           defects=[{"group": "crack"}],
                           boundary=[{"group": "top", "traction": [0.0, 1.0]},
                                     {"group": "bottom", "traction": [0.0, -1.0]}])
            qp, sol, _, t_all = _solve(p)
            it = qp.interface
            j = int(np.argmin(qp.geometry.nodes[0, it.lower]))           # the mouth (x = 0)
            cmod = float((qp.B @ sol.x)[j])
            rows.append({"a_over_b": s, "mesh_size": hs, "tip_size": tip, "n": qp.n, "cmod": cmod, "tada": exact,
                         "error_pct": 100 * (cmod / exact - 1), "time_s": t_all})
    return rows


# --------------------------------------------------------------------------- 4. cylinder vs box
def penny(tmp: Path, quick: bool) -> list[dict]:
    from dualfem.post.fields3d import defect_fields3d
    from dualfem.registry import get_problem

    tilt = math.radians(30)
    normal = np.array([math.sin(tilt), 0.0, math.cos(tilt)])
    sigma_n = math.cos(tilt) ** 2
    levels = ((2.0, 0.25),) if quick else ((2.0, 0.25), (1.5, 0.12), (1.0, 0.08))
    rows = []
    for hs, tip in levels:
        cyl = _file_body(geometry_file=str(EXAMPLES / "cylinder_penny.geo"), mesh_size=hs, tip_size=tip, E=E, nu=NU,
                         delta=1e3, defects=[{"group": "crack"}],
                         boundary=[{"group": "top", "traction": [0.0, 0.0, 1.0]},
                                   {"group": "bottom", "traction": [0.0, 0.0, -1.0]}])
        box = get_problem("three_d")(width=10.0, depth=10.0, height=10.0, E=E, nu=NU, delta=1e3, mesh_size=hs,
                                     tip_size=tip, defects=[{"shape": "disk", "center": [5.0, 5.0, 5.0],
                                                             "normal": normal.tolist(), "radius": 1.0}],
                                     boundary=[{"side": "top", "traction": [0.0, 0.0, 1.0]},
                                               {"side": "bottom", "traction": [0.0, 0.0, -1.0]}])
        out = {"mesh_size": hs, "tip_size": tip}
        profiles = {}
        for name, prob, centre in (("cylinder", cyl, np.zeros(3)), ("box", box, np.full(3, 5.0))):
            qp, sol, _, t_all = _solve(prob)
            d = defect_fields3d(qp, sol.x)
            rel = d["points"] - centre
            r = np.linalg.norm(rel - np.outer(rel @ normal, normal), axis=1)
            w = np.abs(d["opening"])
            ref = 8 * (1 - NU ** 2) * sigma_n / (math.pi * E) * np.sqrt(np.clip(1 - r ** 2, 0, None))
            inner = r <= 0.8
            out[f"{name}_n"] = qp.n
            out[f"{name}_err_pct"] = 100 * float(np.linalg.norm(w[inner] - ref[inner]) / np.linalg.norm(ref[inner]))
            out[f"{name}_time_s"] = t_all
            profiles[name] = (r[inner], w[inner])
        # the two bodies' openings compared through the same fit: w ~ c sqrt(1 - r^2) over r <= 0.8
        c = {k: float(np.linalg.lstsq(np.sqrt(1 - v[0] ** 2)[:, None], v[1], rcond=None)[0][0]) for k, v in
             profiles.items()}
        out["c_cyl"], out["c_box"] = c["cylinder"], c["box"]
        out["c_sneddon"] = 8 * (1 - NU ** 2) * sigma_n / (math.pi * E)
        out["cyl_vs_box_pct"] = 100 * (c["cylinder"] / c["box"] - 1)
        rows.append(out)
    return rows


# --------------------------------------------------------------------------- 5. pictures
def pictures(tmp: Path, figdir: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    from dualfem.post.fields import deformed_nodes, stresses
    from dualfem.post.style import FIELD_CMAP, PALETTE

    figdir.mkdir(parents=True, exist_ok=True)
    p = _file_body(geometry_file=str(EXAMPLES / "edge_crack.geo"), mesh_size=0.1, tip_size=0.02, E=E, nu=NU,
                   delta=1e3, defects=[{"group": "crack"}], boundary=[{"group": "top", "traction": [0.0, 1.0]},
                                                                      {"group": "bottom", "traction": [0.0, -1.0]}])
    qp, sol, _, _ = _solve(p)
    body = p.body()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 6.5))
    a1.triplot(body.points[0], body.points[1], body.cells.T, color="0.75", lw=0.4)
    for (name, g), col in zip(sorted((n, g) for n, g in body.groups.items() if g.dim == 1), PALETTE):
        seg = body.points[:, g.elements].transpose(2, 1, 0)
        a1.add_collection(LineCollection(seg, colors=col, lw=3, label=f"group {name!r}"))
    a1.set_aspect("equal")
    a1.set_title("edge_crack.geo: the mesh and its groups")
    a1.legend(loc="upper right", fontsize=8)
    s = stresses(qp, sol.x)
    vm = s["von_mises"]
    xy = deformed_nodes(qp, sol.x, 30.0)
    tpc = a2.tripcolor(xy[0], xy[1], qp.geometry.cells.T, vm, cmap=FIELD_CMAP, shading="flat")
    fig.colorbar(tpc, ax=a2, label="von Mises stress (sigma = 1 on the ends)")
    a2.set_aspect("equal")
    a2.set_title("the solution: von Mises on the body deformed x30")
    for a in (a1, a2):
        a.set_xlabel("x")
        a.set_ylabel("y")
    fig.tight_layout()
    names = ["edge_crack.png"]
    fig.savefig(figdir / names[0], dpi=110)
    plt.close(fig)
    geo = tmp / "kirsch_fig.geo"
    geo.write_text((EXAMPLES / "plate_hole.geo").read_text().replace("h_hole = 0.1;", "h_hole = 0.05;"))
    p = _file_body(geometry_file=str(geo), E=E, nu=NU, defects=[], remote_stress=[[1.0, 0.0], [0.0, 0.0]])
    qp, sol, _, _ = _solve(p)
    s11 = _element_stress(qp, sol.x)[0]
    nodes = qp.geometry.nodes
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    tpc = ax.tripcolor(nodes[0], nodes[1], qp.geometry.cells.T, s11, cmap=FIELD_CMAP, shading="flat", vmin=0,
                       vmax=3)
    ax.triplot(nodes[0], nodes[1], qp.geometry.cells.T, color="w", lw=0.15)
    fig.colorbar(tpc, ax=ax, label="sigma_xx / sigma (Kirsch: 3 at (0, +-a))")
    ax.set_xlim(-4, 4)
    ax.set_ylim(-4, 4)
    ax.set_aspect("equal")
    ax.set_title("plate_hole.geo near the hole (h_hole = 0.05 a)")
    fig.tight_layout()
    names.append("kirsch.png")
    fig.savefig(figdir / names[1], dpi=110)
    plt.close(fig)
    from dualfem.post.figures3d import plot_cut, plot_defect_maps

    ends = [{"group": "top", "traction": [0.0, 0.0, 1.0]}, {"group": "bottom", "traction": [0.0, 0.0, -1.0]}]
    p = _file_body(geometry_file=str(EXAMPLES / "cylinder_penny.geo"), mesh_size=1.0, tip_size=0.08, E=E, nu=NU,
                   delta=1e3, defects=[{"group": "crack"}], boundary=ends)
    qp, sol, _, _ = _solve(p)
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    plot_cut(qp, sol, ax=ax)
    fig.tight_layout()
    names.append("cylinder_cut.png")
    fig.savefig(figdir / names[-1], dpi=110)
    plt.close(fig)
    fig = plot_defect_maps(qp, sol, quantities=("opening", "slip"))
    names.append("cylinder_penny.png")
    fig.savefig(figdir / names[-1], dpi=110)
    plt.close(fig)
    return names


# --------------------------------------------------------------------------- render
def _e(x: float) -> str:
    return f"{x:.1e}"


def render(res: dict, out: Path) -> None:
    L = ["# Bodies from mesh and geometry files: validation", "",
         f"Generated by `python benchmarks/bodies.py --report reports` on {res['machine']}, shared with other "
         f"jobs: times are indicative ({res['when']}; "
         f"{res['wall_s']:.0f} s in all). Every answer: `pdas` through dualfem's runner, certified by the "
         "evaluator. Scene keys and files: docs/bodies.md; the example files: examples/bodies/.", ""]
    L += ["## 1. Round trip: a box scene written as .msh and read back", "",
          "The delta-free mesh of a `thin_defect` gmsh scene (two cracks, one kinked; bottom clamped, top "
          "traction) and of a `three_d` scene (a disk with normal (0.3, 0, 1)) written by `write_msh` (gmsh, "
          "ASCII) and read back as `mesh_file` scenes with the same groups: the largest difference of each "
          "matrix relative to its largest entry.", "",
          "| scene | MSH | unknowns | defect nodes | file | same shapes | K | F | B |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in res["round_trip"]:
        L.append(f"| {r['case']} | {r['msh']} | {r['n']:,} | {r['m']:,} | {r['size_MB']:.1f} MB | {r['same_shape']} | "
                 f"{_e(r['K'])} | {_e(r['F'])} | {_e(r['B'])} |")
    L += ["", "## 2. Kirsch: a plate with a hole under uniaxial tension", "",
          "Square plate of side 40 a, hole of radius a = 1 (`examples/bodies/plate_hole.geo`, element size "
          "`h_hole` on the hole growing to 2 a at the plate's edge), E = 1000, nu = 0.3 (plane strain), "
          "`defects = []`, `remote_stress` sigma_xx = 1 on the outer boundary, no supports (rigid motions "
          "removed). Closed form (infinite plate): sigma_tt = 3 sigma at (0, +-a); the finite plate (d/W = 0.05) "
          "adds about +0.3 % (Heywood's Kt = (2 + (1 - d/W)^3) / (1 - d/W) = 3.008). Recovery: a least-squares "
          "fit sigma_tt = c0 + c1 d + c2 d^2 + c3 s^2 of the P1 element stresses whose centroids lie within 4 "
          "h_hole of the point (d: distance from the edge, s: arc length), c0 taken, the mean of theta = 90 and "
          "270 degrees; beside it the area-weighted nodal average at the edge node.", "",
          "| h_hole / a | unknowns | nodal average | its error vs 3 | fit | its error vs 3 | time |",
          "|---|---|---|---|---|---|---|"]
    for r in res["kirsch"]:
        L.append(f"| {r['h_hole']:g} | {r['n']:,} | {r['hoop_avg']:.4f} | {100 * (r['hoop_avg'] / 3 - 1):+.2f} % | "
                 f"{r['hoop_fit']:.4f} | {100 * (r['hoop_fit'] / 3 - 1):+.2f} % | {r['time_s']:.1f} s |")
    k = res["kirsch"]
    if len(k) >= 2:
        e = [abs(r["hoop_avg"] / 3 - 1) for r in k[-2:]]
        L += ["", f"The nodal average approaches 3 from below, its error falling by {e[0] / e[1]:.2f}x at the last "
              f"halving of h_hole ({100 * e[1]:.2f} % at h_hole = {k[-1]['h_hole']:g} a); the fit overshoots by "
              f"{100 * (k[-1]['hoop_fit'] / 3 - 1):.2f} % there (Heywood's finite plate: +0.26 %)."]
    L += ["", "## 3. An edge crack against Tada's handbook", "",
          "Strip of width b = 1 and height 6 (`examples/bodies/edge_crack.geo` with H = 6), crack of length a from "
          "its left side at mid-height, traction sigma = 1 pulling both ends (no supports), E = 1000, nu = 0.3 "
          "(plane strain), delta = 1e3 (free faces). Reference: Tada, Paris & Irwin, *The Stress Analysis of "
          "Cracks Handbook* (3rd ed., 2000), single edge notched strip in tension: CMOD = 4 sigma a V1(a/b) / E', "
          "V1 = [1.46 + 3.42 (1 - cos(pi a/2b))] / cos^2(pi a/2b), E' = E / (1 - nu^2); the handbook's ends are "
          "infinitely far (here 3 b from the crack). Computed: the normal jump at the mouth node (row of B).", "",
          "| a/b | mesh_size | tip_size | unknowns | CMOD | Tada | error | time |", "|---|---|---|---|---|---|---|---|"]
    for r in res["edge_crack"]:
        L.append(f"| {r['a_over_b']:g} | {r['mesh_size']:g} | {r['tip_size']:g} | {r['n']:,} | {r['cmod']:.5g} | "
                 f"{r['tada']:.5g} | {r['error_pct']:+.2f} % | {r['time_s']:.1f} s |")
    L += ["", "## 4. A 3D body from a .geo file: a cylinder with an inclined penny against the box penny", "",
          "Cylinder of radius 5 a and height 10 a (`examples/bodies/cylinder_penny.geo`), penny of radius a = 1 "
          "at its centre with its normal tilted 30 degrees from z; the `three_d` box of side 10 a with the same "
          "disk; both with traction sigma_zz = 1 on their ends, no supports, E = 1000, nu = 0.3, delta = 1e3, the "
          "same mesh_size and tip_size. Sneddon (infinite body, normal stress sigma_n = sigma cos^2 30 = 0.75 on "
          "the crack's plane): w = 8 (1 - nu^2) sigma_n / (pi E) sqrt(a^2 - r^2). Relative L2 error of the "
          "opening over r <= 0.8 a, and the fitted amplitude c of w = c sqrt(1 - r^2) for both bodies.", "",
          "| mesh_size | tip_size | cylinder unknowns | box unknowns | cylinder L2 error | box L2 error | "
          "c cylinder / c box | c cylinder / Sneddon |", "|---|---|---|---|---|---|---|---|"]
    for r in res["penny"]:
        L.append(f"| {r['mesh_size']:g} | {r['tip_size']:g} | {r['cylinder_n']:,} | {r['box_n']:,} | "
                 f"{r['cylinder_err_pct']:.1f} % | {r['box_err_pct']:.1f} % | {r['cyl_vs_box_pct']:+.2f} % | "
                 f"{100 * (r['c_cyl'] / r['c_sneddon'] - 1):+.1f} % |")
    L += ["", "## 5. Pictures", ""]
    for name in res["figures"]:
        L.append(f"![{name}](bodies/{name})")
        L.append("")
    out.write_text("\n".join(L) + "\n", encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--report", default="reports", help="folder of bodies.md and bodies/*.png")
    ap.add_argument("--quick", action="store_true", help="the coarse levels only")
    ap.add_argument("--render-only", action="store_true", help="re-render from REPORT/bodies.json")
    args = ap.parse_args(argv)
    report = Path(args.report)
    if args.render_only:
        render(json.loads((report / "bodies.json").read_text(encoding="utf-8")), report / "bodies.md")
        return 0
    t0 = time.perf_counter()
    res: dict = {"machine": f"{platform.machine()}, {os.cpu_count()} cores, OMP/MKL threads "
                            f"{os.environ['OMP_NUM_THREADS']}",
                 "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for name, fn in (("round_trip", round_trip), ("kirsch", kirsch), ("edge_crack", edge_crack),
                         ("penny", penny)):
            t = time.perf_counter()
            res[name] = fn(tmp, args.quick)
            print(f"{name}: {time.perf_counter() - t:.1f} s", file=sys.stderr, flush=True)
        res["figures"] = pictures(tmp, report / "bodies")
    res["wall_s"] = time.perf_counter() - t0
    report.mkdir(parents=True, exist_ok=True)
    (report / "bodies.json").write_text(json.dumps(res, indent=1), encoding="utf-8")
    render(res, report / "bodies.md")
    print(f"wrote {report / 'bodies.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
