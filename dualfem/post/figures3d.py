"""Figures of a 3D solution: maps of opening, slip and contact pressure over each defect surface, and
a plane cut through the body coloured by the von Mises stress (matplotlib, Agg-safe).

The defect maps are drawn in the defect's own plane coordinates (the plane through its nodes' centroid
orthogonal to their mean normal; for a curved defect, its projection), triangulated by the defect's
surface triangles when the QP has them (``qp.interface.faces``: (n_faces, 3) node ids of the "-"
face, the front nodes single; the front drawn with opening and slip 0), else by a Delaunay
triangulation of the projected defect nodes restricted to the defect's outline. Units: lengths of the
scene, opening and slip in displacement units, pressure in stress units (E's).
"""
from __future__ import annotations

import numpy as np

from dualfem.core.errors import InputError
from dualfem.post.fields3d import defect_fields3d, plane_cut, stresses3d
from dualfem.post.style import FIELD_CMAP

#: defects drawn at most (one row of panels each)
MAX_DEFECT_ROWS = 4
#: a map whose largest |value| is at most this times its scale (opening, slip: the largest nodal
#: displacement; pressure: the largest von Mises stress) is rounding, not a field: drawn as "closed",
#: "no slip" or "no contact pressure"
ROUNDING = 1e-9
#: what a map at rounding level says, per quantity
ZERO_SAYS = {"opening": "closed", "slip": "no slip", "pressure": "no contact pressure"}


def axis_name(v) -> str:
    """A unit direction as text: ``x``, ``-z`` for a coordinate axis, else ``(0.707, 0.707, 0)``."""
    v = np.asarray(v, float)
    k = int(np.argmax(np.abs(v)))
    if abs(abs(v[k]) - 1.0) < 1e-9:
        return ("-" if v[k] < 0 else "") + "xyz"[k]
    return "(" + ", ".join(f"{c:.3g}" for c in np.where(np.abs(v) < 1e-12, 0.0, v)) + ")"


def _scales(qp, sol, d: dict, qs: list[str]) -> dict[str, float]:
    """The scale each quantity is compared with (:data:`ROUNDING`)."""
    from dualfem.post.fields import nodal_displacement

    out = {}
    if "opening" in qs or "slip" in qs:
        u = float(np.abs(nodal_displacement(qp, sol.x)).max(initial=0.0))
        out.update(opening=u, slip=u)
    if "pressure" in qs:
        out["pressure"] = float(np.nanmax(stresses3d(qp, sol.x)["von_mises"], initial=0.0))
    return out


def _zero_panel(ax, tri, q: str, vmax: float) -> None:
    """A map at rounding level: the defect's outline in grey and what it means (no colour scale)."""
    from matplotlib.colors import ListedColormap

    ax.tripcolor(tri, np.zeros(tri.x.size), shading="flat", cmap=ListedColormap(["0.88"]))
    why = f"max |{q}| = {vmax:.1e}: rounding" if vmax > 0 else f"{q} 0 everywhere"
    ax.text(0.5, 0.5, f"{ZERO_SAYS.get(q, 'zero')}\n({why})", transform=ax.transAxes,
            ha="center", va="center", fontsize=8.5, bbox={"facecolor": "white", "alpha": 0.85, "lw": 0})


def plane_frame(points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centre (3,), in-plane unit vectors e1, e2 (3,)) of a defect from its nodes (k, 3) and normals (k, 3)."""
    c = points.mean(axis=0)
    nv = normals.mean(axis=0)
    if np.linalg.norm(nv) < 1e-12:
        nv = normals[0]
    return (c, *plane_basis(nv))


def plane_basis(normal) -> tuple[np.ndarray, np.ndarray]:
    """An orthonormal pair (e1, e2) spanning the plane orthogonal to ``normal``, with e1 x e2 = its direction."""
    nv = np.asarray(normal, float) / np.linalg.norm(normal)
    e1 = np.cross(nv, np.eye(3)[int(np.argmin(np.abs(nv)))])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(nv, e1)


def _surface(qp, d: dict, k: int):
    """(node coordinates (p, 3), triangles (nf, 3) into them or None, row of each vertex (p,) or -1 at the
    front) of defect ``k``, from ``qp.interface.faces`` ((n_faces, 3) node ids of the "-" face)."""
    faces = None if qp.interface is None or qp.interface.faces is None else qp.interface.faces.T
    rows = np.flatnonzero(d["defect_id"] == k)
    if faces is None or not np.size(faces):
        return d["points"][rows], None, rows
    f = np.asarray(faces, int)
    row_of = np.full(qp.geometry.nodes.shape[1], -1)
    row_of[d["lower"]] = np.arange(d["lower"].size)
    mine = np.any(np.isin(row_of[f], rows), axis=0)
    f = f[:, mine]
    verts, inv = np.unique(f, return_inverse=True)
    return qp.geometry.nodes[:, verts].T, inv.reshape(f.shape).T, row_of[verts]


def _triangulation(xy: np.ndarray, triangles):
    import matplotlib.tri as mtri

    if triangles is not None:
        return mtri.Triangulation(xy[:, 0], xy[:, 1], triangles)
    tri = mtri.Triangulation(xy[:, 0], xy[:, 1])
    # drop Delaunay triangles much longer than the typical node spacing (concave outlines)
    e = xy[tri.triangles]
    longest = np.max(np.linalg.norm(e - np.roll(e, 1, axis=1), axis=2), axis=1)
    tri.set_mask(longest > 3 * np.median(longest))
    return tri


def plot_defect_maps(qp, sol, *, fig=None, quantities=("opening", "slip", "pressure")):
    """One row per defect (at most :data:`MAX_DEFECT_ROWS`), one panel per quantity; returns the figure.
    A quantity at rounding level (:data:`ROUNDING`) is drawn as a grey surface that says so ("closed",
    "no slip", "no contact pressure"), without a colour scale. Axes: the defect's in-plane directions
    (:func:`plane_frame`), lengths of the scene from the defect's centre."""
    import matplotlib.pyplot as plt

    if sol.x is None:
        raise InputError(f"no solution to draw (status {sol.status})")
    d = defect_fields3d(qp, sol.x, sol.multipliers)
    ids = np.unique(d["defect_id"])[:MAX_DEFECT_ROWS]
    qs = [q for q in quantities if q in d]
    scale = _scales(qp, sol, d, qs)
    fig = fig or plt.figure(figsize=(3.6 * len(qs), 3.1 * len(ids)), layout="constrained")
    axes = np.atleast_2d(fig.subplots(len(ids), len(qs), squeeze=False))
    for r, k in enumerate(ids):
        rows = np.flatnonzero(d["defect_id"] == k)
        c, e1, e2 = plane_frame(d["points"][rows], d["normal"][rows])
        pts, triangles, vrows = _surface(qp, d, k)
        xy = np.stack([(pts - c) @ e1, (pts - c) @ e2], axis=1)
        tri = _triangulation(xy, triangles)
        for col, q in enumerate(qs):
            ax = axes[r, col]
            # the front is sealed: opening and slip 0 there; the pressure is drawn as 0 where undefined
            v = np.where(vrows >= 0, np.nan_to_num(d[q][np.maximum(vrows, 0)], nan=0.0), 0.0)
            vmax = float(np.abs(v).max(initial=0.0))
            closed = vmax <= ROUNDING * scale.get(q, 0.0) or vmax == 0.0
            if closed:
                _zero_panel(ax, tri, q, vmax)
            else:
                im = ax.tripcolor(tri, v, shading="gouraud", cmap=FIELD_CMAP)
                fig.colorbar(im, ax=ax, shrink=0.8).ax.tick_params(labelsize=7)
            ax.set_aspect("equal")
            ax.set_title(f"defect {k}: {q}" + (f" ({ZERO_SAYS.get(q, 'zero')})" if closed else ""), fontsize=9)
            ax.set_xlabel(f"along {axis_name(e1)}", fontsize=8)
            ax.set_ylabel(f"along {axis_name(e2)}", fontsize=8)
            ax.tick_params(labelsize=7)
    return fig


def plot_cut(qp, sol, *, origin=None, normal=None, ax=None, scale: float = 0.0):
    """The section of the body by a plane (default: through the first defect's centre, containing its
    normal), coloured by the von Mises stress per tetrahedron; the defect nodes near the plane are marked.
    ``scale`` > 0 draws the section at displaced positions (u times scale). The title names the plane
    (its origin and normal), the axes its in-plane directions. Returns the axes."""
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    if sol.x is None:
        raise InputError(f"no solution to draw (status {sol.status})")
    g = qp.geometry
    d = defect_fields3d(qp, sol.x)
    rows = np.flatnonzero(d["defect_id"] == d["defect_id"].min())
    c, e1, e2 = plane_frame(d["points"][rows], d["normal"][rows])
    n_def = np.cross(e1, e2)
    if normal is None:        # the plane through the defect's centre spanned by e1 and its normal: the
        normal, a1, a2 = e2, e1, n_def      # defect is the horizontal line, its normal points up
    else:
        normal = np.asarray(normal, float) / np.linalg.norm(normal)
        a1, a2 = plane_basis(normal)
    origin = c if origin is None else np.asarray(origin, float)
    polys, tets, bary = plane_cut(g.nodes, g.cells[:4], origin, normal)      # quadratic cells: their corners
    if scale:
        from dualfem.post.fields import nodal_displacement

        u = nodal_displacement(qp, sol.x)
        polys = polys + scale * np.einsum("kva,aki->kvi", bary, u[g.cells[:4, tets]])
    nv = np.asarray(normal, float)
    xy = np.stack([(polys - origin) @ a1, (polys - origin) @ a2], axis=-1)
    vm = stresses3d(qp, sol.x)["von_mises"][tets]
    ax = ax or plt.figure(figsize=(5, 4.4), layout="constrained").add_subplot()
    pc = PolyCollection(xy, array=vm, cmap=FIELD_CMAP, edgecolors="face", linewidths=0.2)
    ax.add_collection(pc)
    ax.autoscale_view()
    ax.set_aspect("equal")
    near = np.abs((d["points"] - origin) @ nv) < 0.5 * np.ptp(xy[..., 0]) / max(np.sqrt(len(tets)), 1)
    pts = d["points"][near]
    ax.plot((pts - origin) @ a1, (pts - origin) @ a2, "w.", ms=2, label="defect nodes")
    ax.figure.colorbar(pc, ax=ax, shrink=0.8, label="von Mises stress (units of E)")
    where = f"plane through ({', '.join(f'{v:.3g}' for v in origin)}), normal {axis_name(nv)}"
    ax.set_title(("cut across defect 0 (its normal up)" if scale == 0 else
                  f"cut, displacements x {scale:g}") + f"\n{where}", fontsize=9)
    ax.set_xlabel(f"along {axis_name(a1)} from the plane's origin (length units of the scene)", fontsize=8)
    ax.set_ylabel(f"along {axis_name(a2)}", fontsize=8)
    return ax
