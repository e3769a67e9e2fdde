"""3D stress intensity factors along a front by the interaction integral in domain form (Shih, Moran and Nakamura
1986; Gosz and Moran 2002, without their curvature terms), with the plane-strain and anti-plane Williams fields.

At front node P with the frame (e1, e2, e3) of :func:`dualfem.post.sif.front_frames_3d` (tensors in that
frame), the weight ``q(x) = q_r(r) q_s(s)`` with r the distance of x to the front (a polyline of its edges),
s the position of its nearest front point along e3, ``q_r`` = 1 at the front falling linearly to 0 at
``r_out`` and ``q_s`` the hat 1 - abs(s)/``r_out``, P1 nodal values on the tetrahedra,

    I = [ sum over tetrahedra of volume x (sigma_ij u^a_i,1 + sigma^a_ij u_i,1 - sigma^a_ik eps_ik delta_1j) q_,j
          - sum over face nodes of q f_i u^a_i,1 ] / (integral of q along the front),

with f the nodal forces the faces receive (``K_fixed x``: contact, the delta term, face loads; lumped at the
nodes). The auxiliary fields are those of a straight front through P, at the polar coordinates (r, theta) of
x about its nearest front point (r measured to the curved front, theta from e1 toward e2). Then
``K_I = E' I_I / 2``, ``K_II = E' I_II / 2`` (``E' = E / (1 - nu^2)``) and ``K_III = G I_III``. The front's
curvature within ``r_out`` is neglected (an error of order r_out / radius of curvature).
"""
from __future__ import annotations

import numpy as np

from dualfem.core.errors import InputError
from dualfem.post.sif import StressIntensity, check_x, distance_to_front, front_frames_3d, node_cells, parts
from dualfem.post.sif_integral import williams


def _aux(r: np.ndarray, th: np.ndarray, mode: int, G: float, nu: float) -> tuple[np.ndarray, np.ndarray]:
    """(sigma^a (p, 3, 3), u^a_i,1 (p, 3)) of a unit-K mode 1, 2 (plane strain) or 3 (anti-plane) front."""
    p = r.size
    S, U = np.zeros((p, 3, 3)), np.zeros((p, 3))
    if mode in (1, 2):
        (s11, s22, s12), (u1, u2) = williams(r, th, mode, G, 3 - 4 * nu)
        S[:, 0, 0], S[:, 1, 1], S[:, 2, 2] = s11, s22, nu * (s11 + s22)
        S[:, 0, 1] = S[:, 1, 0] = s12
        U[:, 0], U[:, 1] = u1, u2
    else:
        f = 1.0 / np.sqrt(2 * np.pi * r)
        S[:, 0, 2] = S[:, 2, 0] = -f * np.sin(th / 2)
        S[:, 1, 2] = S[:, 2, 1] = f * np.cos(th / 2)
        g, dg = np.sin(th / 2), np.cos(th / 2) / 2                        # u3 = 2/G sqrt(r / 2 pi) g(theta)
        U[:, 2] = 2 / (G * np.sqrt(2 * np.pi)) * (np.cos(th) * g - 2 * np.sin(th) * dg) / (2 * np.sqrt(r))
    return S, U


def interaction3d(qp, x, r_out: float | None = None) -> StressIntensity:
    """K_I, K_II, K_III at every 3D front node by the interaction integral (module docstring); ``r_out``: the
    domain's radius (length; default an eighth of the defect's largest extent from the node, at least two
    elements)."""
    it, g, mat = parts(qp)
    if it.dim != 3:
        raise InputError("interaction3d needs a 3D QP: use dualfem.post.sif_integral.interaction in 2D")
    if r_out is not None and not (isinstance(r_out, (int, float)) and np.isfinite(r_out) and r_out > 0):
        raise InputError(f"r_out must be a finite length > 0, got {r_out!r}")
    x = check_x(qp, x)
    from dualfem.numerics.p1 import tet_gradients
    from dualfem.post.fields import nodal_displacement

    pts, tets = g.nodes, g.cells
    G, nu = mat.E / (2 * (1 + mat.nu)), mat.nu
    lam = 2 * G * nu / (1 - 2 * nu)
    grad, vol = tet_gradients(pts, tets)
    vol = np.abs(vol)
    u = nodal_displacement(qp, x - (qp.shift.x if qp.shift is not None else 0.0))     # (nn, 3)
    Du = np.einsum("tic,idt->tcd", u[tets.T], grad)                                    # d u_c / d x_d
    eps = 0.5 * (Du + Du.transpose(0, 2, 1))
    sig = lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 2 * G * eps
    traction = _face_tractions3d(qp, x)
    frames, hs, edges = front_frames_3d(it, pts)
    node_tets = node_cells(tets, pts.shape[1])
    from scipy.spatial import cKDTree

    tree = cKDTree(pts.T)
    q = np.zeros(pts.shape[1])                       # the weight q of the current front node (reset after it)
    K = np.zeros((it.front.size, 3))
    radius = np.zeros(it.front.size)
    for k, tip in enumerate(it.front):
        F, P, d = frames[k], pts[:, tip], int(it.front_id[k])
        e = edges[d]
        if e.size == 0:
            raise InputError(f"defect {d} has no front edges (interface.faces): no 3D interaction integral")
        mine = np.r_[it.lower[it.defect_id == d], it.front[it.front_id == d]]
        extent = float(np.linalg.norm(pts[:, mine] - P[:, None], axis=0).max())
        ro = max(0.125 * extent, 2 * hs[k]) if r_out is None else r_out
        if ro < hs[k]:
            raise InputError(f"r_out = {ro:.3g} at front node {int(tip)} spans less than one element ({hs[k]:.3g})")
        e = e[np.minimum(*(np.linalg.norm(pts[:, e[:, j]] - P[:, None], axis=0) for j in (0, 1))) < 3 * ro]
        near = np.asarray(tree.query_ball_point(P, 1.5 * ro), dtype=np.int64)
        r_n, foot = distance_to_front(pts[:, near], pts[:, e[:, 0]], pts[:, e[:, 1]])
        q[near] = np.clip(1 - r_n / ro, 0, 1) * np.clip(1 - np.abs(F[2] @ (foot - P[:, None])) / ro, 0, 1)
        fq = q[it.front[it.front_id == d]]
        qa, qb = q[e[:, 0]], q[e[:, 1]]
        length = float(np.sum(0.5 * (qa + qb) * np.linalg.norm(pts[:, e[:, 1]] - pts[:, e[:, 0]], axis=0)))
        if length <= 0 or fq.max() <= 0:
            raise InputError(f"the domain of front node {int(tip)} holds no front")
        T = np.unique(np.concatenate([node_tets[n] for n in near[q[near] > 0]]))
        gq = np.einsum("it,idt->td", q[tets[:, T]], grad[:, :, T]) @ F.T                 # grad q, tip frame
        C = pts[:, tets[:, T]].mean(axis=1)
        rc, fc = distance_to_front(C, pts[:, e[:, 0]], pts[:, e[:, 1]])
        dv = F @ (C - fc)
        th = np.arctan2(dv[1], dv[0])
        S = np.einsum("ab,tbc,dc->tad", F, sig[T], F)
        D = np.einsum("ab,tbc,dc->tad", F, Du[T], F)
        Ep = np.einsum("ab,tbc,dc->tad", F, eps[T], F)
        faces = _face_points(it, pts, q, traction, e, F) if traction is not None else None
        for mode in (1, 2, 3):
            Sa, Ua = _aux(np.maximum(rc, 1e-300), th, mode, G, nu)
            W = np.einsum("tij,tij->t", Sa, Ep)
            integrand = np.einsum("tij,ti->tj", S, Ua) + np.einsum("tij,ti->tj", Sa, D[:, :, 0])
            integrand[:, 0] -= W
            I = float(np.sum(vol[T] * np.einsum("tj,tj->t", integrand, gq)))
            if faces is not None:
                wq, rq, tq, side = faces
                c = np.stack([_aux(np.ones(1), np.array([sd * np.pi]), mode, G, nu)[1][0] for sd in (1.0, -1.0)])
                cq = c[np.where(side > 0, 0, 1)]                                            # (faces, 3)
                I -= float(np.sum(wq / np.sqrt(rq) * np.einsum("fpi,fi->fp", tq, cq)))
            K[k, mode - 1] = I / length * ((mat.E / (1 - nu ** 2)) / 2 if mode < 3 else G)
        radius[k] = ro
        q[near] = 0.0
    return StressIntensity(3, it.front.copy(), pts[:, it.front].T.copy(), it.front_id.copy(), K[:, 0], K[:, 1],
                           K[:, 2], frames, "interaction", radius)


def _side(it, nodes: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """+1 for a node on the face e2 points to ("+" copies when the normal agrees with e2), -1 on the other."""
    up = np.zeros(int(nodes.max(initial=0)) + 1 if nodes.size else 0)
    keep_u, keep_l = it.upper < up.size, it.lower < up.size
    up[it.upper[keep_u]] = it.normals[keep_u] @ e2
    up[it.lower[keep_l]] = -(it.normals[keep_l] @ e2)
    return np.sign(up[nodes])


def _face_tractions3d(qp, x: np.ndarray) -> np.ndarray | None:
    """(3, n_nodes): the tractions the faces receive, ``K_fixed x`` (else ``K x``) at the face nodes' unknowns over
    their nodal areas, 0 elsewhere; None when every one is 0 (a free crack) or the QP has no face triangles."""
    it = qp.interface
    if it.faces is None or it.faces.size == 0:
        return None
    fx = (qp.local.K_fixed if qp.local is not None else qp.K) @ x
    out = np.zeros((3, qp.geometry.nodes.shape[1]))
    w = np.maximum(it.weights, 1e-300)
    for nodes, dofs in ((it.upper, it.plus_dofs), (it.lower, it.minus_dofs)):
        out[:, nodes] = fx[dofs].T / w
    return out if np.any(out) else None


#: Gauss-Legendre on [0, 1], 4 points, for both coordinates of the face rule
_G4X, _G4W = (np.polynomial.legendre.leggauss(4)[0] + 1) / 2, np.polynomial.legendre.leggauss(4)[1] / 2


def _face_points(it, pts: np.ndarray, q: np.ndarray, traction: np.ndarray, edges: np.ndarray, F: np.ndarray):
    """The face integral's quadrature on both faces of the triangles with q > 0: weights x q (faces, 16), r to the
    front (faces, 16), tractions in the tip frame (faces, 16, 3) and the side (faces,) (+1: the face e2 points to).

    Each triangle is mapped from its vertex farthest from the front, ``x = V2 + sigma (V0 + tau (V1 - V0) - V2)``,
    with ``sigma = 1 - rho^2`` so that the r^-1/2 of the auxiliary fields at the edge nearest the front is
    integrated exactly enough by Gauss points in (rho, tau); q and the traction are linear on the triangle (a front
    vertex takes the mean traction of the triangle's other vertices)."""
    f = it.faces[np.any(q[it.faces] > 0, axis=1)]
    if f.size == 0:
        return None
    is_front = np.isin(f, it.front)
    f = f[~np.all(is_front, axis=1)]
    is_front = is_front[~np.all(is_front, axis=1)]
    plus = np.arange(pts.shape[1])
    plus[it.lower] = it.upper
    r_v, _ = distance_to_front(pts[:, f.ravel()], pts[:, edges[:, 0]], pts[:, edges[:, 1]])
    order = np.argsort(r_v.reshape(f.shape), axis=1)                    # V0, V1 nearest the front, V2 farthest
    f = np.take_along_axis(f, order, axis=1)
    is_front = np.take_along_axis(is_front, order, axis=1)
    rho2, tau2 = np.meshgrid(_G4X, _G4X, indexing="ij")
    wr = np.outer(_G4W, _G4W).ravel()
    sig, tau = (1 - rho2 ** 2).ravel(), tau2.ravel()
    lam = np.stack([sig * (1 - tau), sig * tau, 1 - sig], axis=1)       # barycentric of V0, V1, V2 (16, 3)
    V = pts[:, f]                                                        # (3, faces, 3)
    area2 = np.linalg.norm(np.cross((V[:, :, 1] - V[:, :, 0]).T, (V[:, :, 2] - V[:, :, 0]).T), axis=1)
    X = np.einsum("kfa,pa->kfp", V, lam)
    rq, _ = distance_to_front(X.reshape(3, -1), pts[:, edges[:, 0]], pts[:, edges[:, 1]])
    jac = area2[:, None] * sig[None, :] * 2 * np.sqrt(1 - sig)[None, :]  # dA = 2 A sigma dsigma dtau, dsigma = 2 rho
    out = []
    for ids in (f, plus[f]):
        T = (F @ traction[:, ids.ravel()]).T.reshape(*ids.shape, 3)     # (faces, 3 vertices, 3)
        mean = (T * ~is_front[:, :, None]).sum(axis=1) / np.maximum((~is_front).sum(axis=1), 1)[:, None]
        T = np.where(is_front[:, :, None], mean[:, None, :], T)
        qT = T * q[ids][:, :, None]
        tq = np.einsum("fai,pa->fpi", qT, lam)
        inner = np.argmax(~is_front, axis=1)
        side = _side(it, ids[np.arange(len(ids)), inner], F[1])
        out.append((jac * wr[None, :], rq.reshape(len(f), -1), tq, side))
    return (np.concatenate([o[0] for o in out]), np.concatenate([o[1] for o in out]),
            np.concatenate([o[2] for o in out]), np.concatenate([o[3] for o in out]))
