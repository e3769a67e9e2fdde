"""2D stress intensity factors by the interaction integral (Yau, Wang and Corten 1980) with the auxiliary
Williams fields, in its domain form over a ring of elements around each tip (Moran and Shih 1987).

With the tip frame of :mod:`dualfem.post.sif` (``e1`` the direction of travel, ``e2`` = ``e1`` turned by +90
degrees; all tensors below in that frame), the FE fields (sigma, u) per triangle and the auxiliary fields
(sigma^a, u^a) of a pure mode I or mode II tip with unit K,

    I = sum over triangles of area x [sigma_ij u^a_i,1 + sigma^a_ij u_i,1 - sigma^a_ik eps_ik delta_1j] q_,j
        - integral over the two faces of q t_i u^a_i,1 ds,

where q is 1 within ``r_in`` of the tip, 0 beyond ``r_out`` and linear in r between (P1 nodal values: only the
ring's triangles contribute), and t the tractions the faces receive (contact, the delta term, face loads;
zero on a free crack): nodal forces ``K_fixed x`` at the face unknowns over the nodal weights, linear along each
face between its nodes (the tip takes its nearest node's), integrated against the ``r^-1/2`` of ``u^a_i,1``
exactly in ``sqrt(r)`` by Gauss points. Then
``K_I = E' I_I / 2`` and ``K_II = E' I_II / 2`` with ``E' = E`` (plane stress) or ``E / (1 - nu^2)``
(plane strain). The ring must not reach the body's outer boundary nor another defect: the default
``r_out`` is a quarter of the defect's length, cut to 0.8 of the distance to the nearest outer-boundary or
other-defect node; ``r_in = r_out / 2``.
"""
from __future__ import annotations

import numpy as np

from dualfem.core.errors import InputError
from dualfem.post.sif import StressIntensity, check_x, kolosov, node_cells, parts, tip_frames_2d


def williams(r: np.ndarray, th: np.ndarray, mode: int, G: float, kappa: float):
    """The auxiliary Williams fields of a unit-K mode-``mode`` tip at polar (r, theta) of the tip frame:
    stresses (s11, s22, s12) and the x1-derivatives (u1_1, u2_1) of the displacements, each shaped like r.

    Displacements ``u = sqrt(r / (2 pi)) / (2 G) g(theta)``, so ``d u / d x1 = (cos(theta) g - 2 sin(theta)
    g'(theta)) / (2 sqrt(r)) sqrt(1 / (2 pi)) / (2 G)``."""
    c, s = np.cos(th / 2), np.sin(th / 2)
    c3, s3 = np.cos(1.5 * th), np.sin(1.5 * th)
    f = 1.0 / np.sqrt(2 * np.pi * r)
    if mode == 1:
        sig = (f * c * (1 - s * s3), f * c * (1 + s * s3), f * c * s * c3)
        g = (c * (kappa - 1 + 2 * s * s), s * (kappa + 1 - 2 * c * c))
        dg = (-s / 2 * (kappa - 1 + 2 * s * s) + 2 * s * c * c, c / 2 * (kappa + 1 - 2 * c * c) + 2 * s * s * c)
    elif mode == 2:
        sig = (-f * s * (2 + c * c3), f * s * c * c3, f * c * (1 - s * s3))
        g = (s * (kappa + 1 + 2 * c * c), -c * (kappa - 1 - 2 * s * s))
        dg = (c / 2 * (kappa + 1 + 2 * c * c) - 2 * s * s * c, s / 2 * (kappa - 1 - 2 * s * s) + 2 * s * c * c)
    else:
        raise ValueError(f"mode must be 1 or 2, got {mode}")
    pre = 1.0 / (2 * G * np.sqrt(2 * np.pi)) / (2 * np.sqrt(r))
    du = tuple(pre * (np.cos(th) * gi - 2 * np.sin(th) * dgi) for gi, dgi in zip(g, dg))
    return sig, du


def _outer_nodes(cells: np.ndarray, face_nodes: np.ndarray) -> np.ndarray:
    """Nodes on the body's outer boundary: the ends of edges used by one triangle, less the defect faces'."""
    e = np.sort(np.concatenate([cells[[0, 1]].T, cells[[1, 2]].T, cells[[2, 0]].T]), axis=1)
    u, cnt = np.unique(e, axis=0, return_counts=True)
    b = u[cnt == 1]
    b = b[~np.all(np.isin(b, face_nodes), axis=1)]
    return np.unique(b)


def _radii(k: int, it, pts: np.ndarray, outer: np.ndarray, r_out: float | None) -> tuple[float, float]:
    """(r_in, r_out) of tip k (module docstring); InputError when no ring fits."""
    d = it.front_id[k]
    tip = pts[:, it.front[k]]
    mine = np.r_[it.lower[it.defect_id == d], it.upper[it.defect_id == d], it.front[it.front_id == d]]
    others = np.r_[it.lower[it.defect_id != d], it.front[it.front_id != d]]
    tips = pts[:, it.front[it.front_id == d]]
    length = float(np.max(np.hypot(*(pts[:, mine] - tip[:, None])))) if tips.shape[1] else 0.0
    far = [np.hypot(*(pts[:, nodes] - tip[:, None])).min() for nodes in (outer, others) if nodes.size]
    limit = 0.8 * min(far) if far else np.inf
    ro = min(0.25 * length, limit) if r_out is None else float(r_out)
    if not (np.isfinite(ro) and 0 < ro <= limit):
        raise InputError(f"r_out must be in (0, {limit:.4g}] at tip {k} (the ring must stay off the outer "
                         f"boundary and the other defects), got {ro!r}")
    return 0.5 * ro, ro


def interaction(qp, x, r_out: float | None = None) -> StressIntensity:
    """K_I, K_II at every 2D tip by the interaction integral (module docstring); ``r_out``: the ring's outer
    radius (length; default a quarter of the defect's length, kept off the boundary and other defects)."""
    it, g, mat = parts(qp)
    if it.dim != 2:
        raise InputError("the interaction integral is 2D only here: use method 'fit' or 'extrapolate' in 3D")
    if r_out is not None and not (isinstance(r_out, (int, float)) and np.isfinite(r_out) and r_out > 0):
        raise InputError(f"r_out must be a finite length > 0, got {r_out!r}")
    x = check_x(qp, x)
    from dualfem.core.elasticity import lame
    from dualfem.post.fields import nodal_displacement, shape_gradients

    pts, tri = g.nodes, g.cells
    lam, G = lame(mat.E, mat.nu, mat.plane)
    kappa = kolosov(mat.nu, mat.plane, 2)
    Ep = mat.E if mat.plane == "stress" else mat.E / (1 - mat.nu ** 2)
    grad, area = shape_gradients(pts, tri)
    u = nodal_displacement(qp, x - (qp.shift.x if qp.shift is not None else 0.0))
    du = np.einsum("tic,tid->tcd", u[tri.T], grad)                  # du[t, c, d] = d u_c / d x_d (global)
    eps = 0.5 * (du + du.transpose(0, 2, 1))
    sig = lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(2) + 2 * G * eps
    force = _face_forces(qp, x)
    frames, tip_rows = tip_frames_2d(it, pts)
    outer = _outer_nodes(tri, np.r_[it.lower, it.upper, it.front])
    node_tris = node_cells(tri, pts.shape[1])
    from scipy.spatial import cKDTree

    tree = cKDTree(pts.T)
    q = np.zeros(pts.shape[1])                       # the weight q of the current tip (reset after it)
    K = np.zeros((it.front.size, 2))
    radius = np.zeros(it.front.size)
    for k, tip in enumerate(it.front):
        R = frames[k]
        r_in, ro = _radii(k, it, pts, outer, r_out)
        near = np.asarray(tree.query_ball_point(pts[:, tip], ro), dtype=np.int64)
        q[near] = np.clip((ro - np.hypot(*(pts[:, near] - pts[:, tip][:, None]))) / (ro - r_in), 0.0, 1.0)
        T = np.unique(np.concatenate([node_tris[n] for n in near]))
        gq = np.zeros((tri.shape[1], 2))
        gq[T] = np.einsum("ti,tid->td", q[tri[:, T].T], grad[T]) @ R.T           # grad q in the tip frame
        ring = T[np.abs(gq[T]).sum(axis=1) > 0]
        V = pts[:, tri[:, ring]] - pts[:, tip][:, None, None]               # (2, 3 vertices, ring)
        loc = np.einsum("ab,bvt,pv->apt", R, V, _TRI_X)                   # quadrature points in the tip frame
        rr, th = np.hypot(*loc), np.arctan2(loc[1], loc[0])             # (points, ring)
        S = np.einsum("ab,tbc,dc->tad", R, sig[ring], R)             # FE stress in the tip frame
        D = np.einsum("ab,tbc,dc->tad", R, du[ring], R)              # FE displacement gradient in the frame
        E_ = np.einsum("ab,tbc,dc->tad", R, eps[ring], R)
        faces = _face_tractions(it, tip_rows[k], pts, tip, R, force, q)
        for mode in (1, 2):
            (a11, a22, a12), (v1, v2) = (tuple(_TRI_W @ f for f in fields) for fields in williams(rr, th, mode, G,
                                                                                                 kappa))
            Sa = np.stack([np.stack([a11, a12], 1), np.stack([a12, a22], 1)], 1)
            Ua1 = np.stack([v1, v2], 1)                              # u^a_i,1
            W = np.einsum("tij,tij->t", Sa, E_)
            integrand = (np.einsum("tij,ti->tj", S, Ua1) + np.einsum("tij,ti->tj", Sa, D[:, :, 0])
                         - W[:, None] * np.array([1.0, 0.0]))
            I = float(np.sum(area[ring] * np.einsum("tj,tj->t", integrand, gq[ring])))
            I -= _face_term(faces, mode, G, kappa)
            K[k, mode - 1] = Ep * I / 2
        radius[k] = ro
        q[near] = 0.0
    return StressIntensity(2, it.front.copy(), pts[:, it.front].T.copy(), it.front_id.copy(), K[:, 0], K[:, 1],
                           None, frames, "interaction", radius)


def _face_forces(qp, x: np.ndarray) -> np.ndarray:
    """(2, n_nodes): the nodal forces the faces receive from outside the body's elements, ``K_fixed x`` (the
    stiffness without the delta term: contact, delta term and face loads alike; zero on a free crack); without
    a local part, ``K x`` (the delta term then counts as internal). Nonzero only at defect nodes."""
    it, g = qp.interface, qp.geometry
    Kf = qp.local.K_fixed if qp.local is not None else qp.K
    fx = Kf @ x
    out = np.zeros((2, g.nodes.shape[1]))
    for nodes, dofs in ((it.upper, it.plus_dofs), (it.lower, it.minus_dofs)):
        out[:, nodes] = fx[dofs].T
    return out


#: a degree-4 rule on triangles (Dunavant's 6 points): barycentric coordinates (6, 3) and weights (6,), summing to 1
_TRI_A, _TRI_B = 0.445948490915965, 0.091576213509771
_TRI_X = np.concatenate([np.full((3, 3), c) + (1 - 3 * c) * np.eye(3) for c in (_TRI_A, _TRI_B)])
_TRI_W = np.r_[np.full(3, 0.223381589678011), np.full(3, 0.109951743655322)]

#: Gauss-Legendre points and weights on [0, 1] (exact for degree 5 in sqrt(r))
_GL_X, _GL_W = (np.polynomial.legendre.leggauss(3)[0] + 1) / 2, np.polynomial.legendre.leggauss(3)[1] / 2


def _face_tractions(it, rows: np.ndarray, pts: np.ndarray, tip: int, R: np.ndarray, force: np.ndarray,
                    q: np.ndarray) -> list[tuple[float, np.ndarray, np.ndarray, np.ndarray]]:
    """Per face (upper: theta = pi, lower: -pi): (theta, r, q, t) at the tip and the tip's defect nodes (nearest
    first; ``rows`` from :func:`tip_frames_2d`) while q > 0, t (2, p) the traction in the tip frame."""
    out = []
    r = np.hypot(*(pts[:, it.lower[rows]] - pts[:, tip][:, None]))
    keep = np.r_[True, q[it.lower[rows]][:-1] > 0]                  # up to the first node with q = 0
    rows, r = rows[keep], r[keep]
    side = np.sign(it.normals[rows] @ R[1])                            # +1: the "+" face is the upper one
    w = np.maximum(it.weights[rows], 1e-300)
    for theta, nodes in ((np.pi, np.where(side > 0, it.upper[rows], it.lower[rows])),
                         (-np.pi, np.where(side > 0, it.lower[rows], it.upper[rows]))):
        t = R @ force[:, nodes] / w
        out.append((theta, np.r_[0.0, r], np.r_[q[tip], q[nodes]], np.c_[t[:, :1], t]))
    return out


def _face_term(faces, mode: int, G: float, kappa: float) -> float:
    """The integral over both faces of q t_i u^a_i,1 dr (:func:`_face_tractions`; ``u^a_i,1 = c_i / sqrt(r)``):
    with r = s^2, dr / sqrt(r) = 2 ds, Gauss points in s on every segment, q and t linear in r."""
    total = 0.0
    for theta, r, q, t in faces:
        if r.size < 2:
            continue
        _, (c1, c2) = williams(np.ones(1), np.full(1, theta), mode, G, kappa)
        sa, sb = np.sqrt(r[:-1]), np.sqrt(r[1:])
        s = sa[:, None] + (sb - sa)[:, None] * _GL_X[None, :]           # (segments, points)
        lam = (s * s - r[:-1, None]) / np.maximum(r[1:] - r[:-1], 1e-300)[:, None]
        f = _lin(q, lam) * (c1[0] * _lin(t[0], lam) + c2[0] * _lin(t[1], lam))
        total += float(np.sum(2 * (sb - sa)[:, None] * _GL_W[None, :] * f))
    return total


def _lin(v: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Nodal values v linear on each segment, at the fractions lam (segments, points)."""
    return v[:-1, None] + (v[1:] - v[:-1])[:, None] * lam
