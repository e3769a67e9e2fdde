"""Post-processing of a 3D solution: stresses per P1 tetrahedron, fields on the defect surfaces,
and a plane cut through the body.

Read from the QP alone: ``qp.geometry`` (dim 3: ``nodes`` (3, n_nodes), ``cells`` (4, n_tets),
``node_dofs`` (3, n_nodes)), ``qp.material`` (``E``, ``nu``), ``qp.weights`` (nodal areas of the
defect nodes) and the defect maps ``defect_upper``/``defect_lower`` (node ids of the "+"/"-" copy of
defect node j, row j of B), ``defect_normals`` (the unit normal nu_j pointing to the "+" face; stored
(3, m) or (m, 3)) and ``defect_id``.

Conventions (as in 2D, :mod:`dualfem.post.fields`): strains and stresses are constant per tetrahedron (quadratic
tetrahedra, ``cells`` (10, n): their mean over the tetrahedron, the value at its centroid, where the linear P2
strain of a straight tetrahedron takes its mean), in the units of E, tensor components (not engineering shear),
Voigt order 11, 22, 33, 23, 13, 12. On a defect: ``jump = u+ - u-`` (3-vector), ``opening = jump . nu`` (>= 0 is
admissible), ``slip = |jump - opening nu|`` (the tangential jump's length), ``pressure = mu / w`` (contact
pressure, stress units; mu >= 0 the nodal contact force of row j).
"""
from __future__ import annotations

import numpy as np

from dualfem.core.elasticity import lame
from dualfem.core.errors import InputError
from dualfem.numerics import p1
from dualfem.post.fields import material, nodal_displacement

VOIGT = ("s11", "s22", "s33", "s23", "s13", "s12")


def _geometry3d(qp):
    g = getattr(qp, "geometry", None)
    if g is None or g.dim != 3 or g.cells.shape[0] not in (4, 10):
        raise InputError("3D post-processing needs a tetrahedral mesh (qp.geometry with dim 3 and cells (4, n), "
                         "or (10, n) quadratic)")
    if getattr(g, "element", "P1") != "P1" and g.cells.shape[0] != 10:
        raise InputError(f"3D post-processing of element {g.element!r} needs its quadratic cells (10, n)")
    return g


#: the mid-edge nodes of a quadratic tetrahedron (rows 4..9 of its cell): VTK's tetra10 order
_TET10_EDGES = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))


def tet_gradients(nodes: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of the four P1 shape functions per tetrahedron, shape (nt, 4, 3), and the volumes (nt,)
    (:func:`dualfem.numerics.p1.tet_gradients`, any orientation). Degenerate (zero-volume) tetrahedra are
    refused (InputError)."""
    g, vol = p1.tet_gradients(nodes, tets)
    vol = np.abs(vol)
    if np.any(vol <= 1e-300):
        raise InputError(f"the mesh has {int(np.sum(vol <= 1e-300))} degenerate tetrahedra")
    return np.transpose(g, (2, 0, 1)), vol


def strains3d(qp, x: np.ndarray) -> np.ndarray:
    """Strain tensor per tetrahedron, shape (nt, 3, 3) (symmetric, dimensionless)."""
    g = _geometry3d(qp)
    u = nodal_displacement(qp, x)            # (n_nodes, 3)
    grads, _ = tet_gradients(g.nodes, g.cells[:4])
    if g.cells.shape[0] == 10:               # P2 at the centroid: corners 0, mid-edge node (i, j): g_i + g_j
        grads = np.stack([grads[:, i] + grads[:, j] for i, j in _TET10_EDGES], axis=1)
        Ue = u[g.cells[4:].T]                # (nt, 6, 3)
    else:
        Ue = u[g.cells.T]                    # (nt, 4, 3)
    Du = np.einsum("tai,taj->tij", Ue, grads)    # du_i/dx_j
    return 0.5 * (Du + np.transpose(Du, (0, 2, 1)))


def stresses3d(qp, x: np.ndarray, E: float | None = None, nu: float | None = None) -> dict[str, np.ndarray]:
    """Cauchy stress per tetrahedron (units of E): the six components (:data:`VOIGT`) and ``von_mises``."""
    E, nu, _ = material(qp, E, nu, "strain")
    lam, mu = lame(E, nu, "strain")             # plane strain's constants are those of 3D elasticity
    eps = strains3d(qp, x)
    tr = np.trace(eps, axis1=1, axis2=2)
    sig = 2 * mu * eps + lam * tr[:, None, None] * np.eye(3)
    out = {k: sig[:, i, j] for k, (i, j) in zip(VOIGT, ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)))}
    dev = sig - np.trace(sig, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
    out["von_mises"] = np.sqrt(1.5 * np.einsum("tij,tij->t", dev, dev))
    return out


def defect_normals(qp) -> np.ndarray:
    """The unit normals of the defect nodes, (m, 3) (a 3D QP's ``qp.interface.normals``)."""
    it = getattr(qp, "interface", None)
    if it is None or it.dim != 3:
        raise InputError("3D defect fields need qp.interface, a 3D interface part (a QP file: map_defect_upper, "
                         "map_defect_lower and map_defect_normals (m, 3))")
    return it.normals


def defect_fields3d(qp, x: np.ndarray, multipliers: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per defect node j: ``points`` (m, 3: the "+" copy's position), ``normal`` (m, 3), ``jump`` (m, 3),
    ``opening``, ``slip`` (m,), ``defect_id``, ``upper``/``lower`` node ids; with multipliers also
    ``force`` (= mu) and ``pressure`` (= mu / w; quadratic cells: :func:`p2_pressure`)."""
    g = _geometry3d(qp)
    nrm = defect_normals(qp)
    it = qp.interface
    up, lo = it.upper, it.lower
    u = nodal_displacement(qp, x)
    jump = u[up] - u[lo]
    opening = np.einsum("ij,ij->i", jump, nrm)
    tangential = jump - opening[:, None] * nrm
    out = {"points": g.nodes[:, up].T, "normal": nrm, "jump": jump, "opening": opening,
           "slip": np.linalg.norm(tangential, axis=1), "upper": up, "lower": lo,
           "defect_id": it.defect_id}
    if multipliers is not None:
        mu = np.asarray(multipliers, dtype=float)
        w = np.asarray(qp.weights, dtype=float)
        out["force"] = mu
        with np.errstate(divide="ignore", invalid="ignore"):
            out["pressure"] = np.where(w > 0, mu / np.where(w > 0, w, 1.0), np.nan)
        if g.cells.shape[0] == 10 and it.faces is not None and np.size(it.faces):
            out["pressure"] = p2_pressure(g, it, mu)
    return out


def p2_pressure(g, it, mu: np.ndarray) -> np.ndarray:
    """Contact pressure (m,) at the pairs of a QP with quadratic tetrahedra: mu / w (the lumped weights) would
    alternate between corners and mid-edge nodes (a uniform pressure p gives each face's corners the consistent
    P2 force 0 and its mid-edge nodes p A / 3). Here a mid-edge pair j gets mu_j / c_j, c_j the sum of A / 3 over
    its defect faces (the consistent force of a unit pressure), and a corner pair the area-weighted mean of the
    mid-edge pairs of its faces: exact for a uniform pressure; the corners' own (small) forces are not used.
    NaN where a pair has no such neighbour."""
    nn = g.nodes.shape[1]
    T = np.asarray(g.cells, dtype=np.int64)
    a, b = T[[0, 1, 0, 0, 1, 2]], T[[1, 2, 2, 3, 3, 3]]                # the edges of _TET10_EDGES
    keys = (np.minimum(a, b) * nn + np.maximum(a, b)).ravel()
    keys, first = np.unique(keys, return_index=True)
    mid_of = T[4:].ravel()[first]
    f = np.asarray(it.faces, dtype=np.int64).T                          # (3, nf) "-" corner ids
    fa, fb = f[[0, 1, 0]], f[[1, 2, 2]]
    k = np.minimum(fa, fb) * nn + np.maximum(fa, fb)
    pos = np.minimum(np.searchsorted(keys, k), keys.size - 1)
    mids = np.where(keys[pos] == k, mid_of[pos], -1)                    # (3, nf)
    row_of = np.full(nn, -1, np.int64)
    row_of[it.lower] = np.arange(it.lower.size)
    rm = np.where(mids >= 0, row_of[np.maximum(mids, 0)], -1)
    P = g.nodes[:, f]
    area = 0.5 * np.linalg.norm(np.cross((P[:, 1] - P[:, 0]).T, (P[:, 2] - P[:, 0]).T), axis=1)
    c = np.zeros(it.lower.size)
    for e in range(3):
        ok = rm[e] >= 0
        np.add.at(c, rm[e][ok], area[ok] / 3)
    p = np.full(it.lower.size, np.nan)
    has = c > 0
    p[has] = mu[has] / c[has]
    pm = np.where(rm >= 0, p[np.maximum(rm, 0)], np.nan)                # (3, nf) the faces' mid-edge pressures
    n_ok = np.sum(np.isfinite(pm), axis=0)
    face_p = np.where(n_ok > 0, np.nansum(np.where(np.isfinite(pm), pm, 0.0), axis=0) / np.maximum(n_ok, 1), 0.0)
    num, den = np.zeros(it.lower.size), np.zeros(it.lower.size)
    rc = row_of[f]
    for e in range(3):
        ok = (rc[e] >= 0) & (n_ok > 0)
        np.add.at(num, rc[e][ok], area[ok] * face_p[ok])
        np.add.at(den, rc[e][ok], area[ok])
    corner = ~has & (den > 0)
    p[corner] = num[corner] / den[corner]
    return p


def plane_cut(nodes: np.ndarray, tets: np.ndarray, origin, normal) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The intersection of the tetrahedra with the plane through ``origin`` with unit ``normal``.

    Returns (polygons (k, 4, 3): each cut tetrahedron's section, a triangle repeating its last vertex
    or a quadrilateral in order; tet ids (k,); barycentric weights (k, 4, 4): polygon vertex v is
    sum_a weights[v, a] * node a of the tet, so nodal fields interpolate linearly onto the section)."""
    o, nv = np.asarray(origin, float), np.asarray(normal, float)
    nv = nv / np.linalg.norm(nv)
    d = np.einsum("i,iat->ta", nv, nodes[:, tets] - o[:, None, None])     # (nt, 4) signed distances
    cut = np.flatnonzero((d.min(axis=1) < 0) & (d.max(axis=1) > 0))
    polys = np.zeros((cut.size, 4, 3))
    bary = np.zeros((cut.size, 4, 4))
    edges = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    for r, t in enumerate(cut):
        pts, ws = [], []
        for a, b in edges:
            da, db = d[t, a], d[t, b]
            if (da < 0) != (db < 0) and da != db:
                s = da / (da - db)
                w = np.zeros(4)
                w[a], w[b] = 1 - s, s
                ws.append(w)
                pts.append(nodes[:, tets[a, t]] * (1 - s) + nodes[:, tets[b, t]] * s)
        pts_a, ws_a = np.array(pts), np.array(ws)
        if len(pts) == 4:                     # order the quadrilateral around its centre
            c = pts_a.mean(axis=0)
            e1 = pts_a[0] - c
            e2 = np.cross(nv, e1)
            order = np.argsort(np.arctan2((pts_a - c) @ e2, (pts_a - c) @ e1))
            pts_a, ws_a = pts_a[order], ws_a[order]
        else:
            pts_a, ws_a = np.vstack([pts_a, pts_a[-1:]]), np.vstack([ws_a, ws_a[-1:]])
        polys[r], bary[r] = pts_a, ws_a
    return polys, cut, bary
