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
    it, g, mat = parts(qp, elements=("P1", "P2"))
    if it.dim != 3:
        raise InputError("interaction3d needs a 3D QP: use dualfem.post.sif_integral.interaction in 2D")
    if r_out is not None and not (isinstance(r_out, (int, float)) and np.isfinite(r_out) and r_out > 0):
        raise InputError(f"r_out must be a finite length > 0, got {r_out!r}")
    x = check_x(qp, x)
    from dualfem.numerics.p1 import tet_gradients
    from dualfem.post.fields import nodal_displacement

    pts, tets = g.nodes, g.cells[:4]
    G, nu = mat.E / (2 * (1 + mat.nu)), mat.nu
    lam = 2 * G * nu / (1 - 2 * nu)
    grad, vol = tet_gradients(pts, tets)
    u = nodal_displacement(qp, x - (qp.shift.x if qp.shift is not None else 0.0))     # (nn, 3)
    if g.element == "P2":           # quadratic tetrahedra: the fields at the 4 points of each (their nodes 4..9)
        Du, xq = _p2_gradients(pts, g.cells, u, grad)
        npt = _TET4.shape[0]
    else:                           # P1: constant per tetrahedron, one point (the centroid)
        Du, xq, npt = np.einsum("tic,idt->tcd", u[tets.T], grad), pts[:, tets].mean(axis=1), 1  # d u_c / d x_d
    eps = 0.5 * (Du + Du.transpose(0, 2, 1))
    body = _Body(pts, tets, grad, np.repeat(np.abs(vol) / npt, npt), Du, eps,
                 lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 2 * G * eps,
                 _face_tractions3d(qp, x), G, nu, xq, npt)
    frames, hs, edges = front_frames_3d(it, pts)
    K = np.zeros((it.front.size, 3))
    radius = np.zeros(it.front.size)
    for d in np.unique(it.front_id):
        if edges[int(d)].size == 0:
            raise InputError(f"defect {int(d)} has no front edges (interface.faces): no 3D interaction integral")
        geo = _FrontGeometry(it, pts, body.xq, edges[int(d)])            # distances to this front, computed once
        mine = np.r_[it.lower[it.defect_id == d], it.front[it.front_id == d]]
        for k in np.flatnonzero(it.front_id == d):
            P = pts[:, it.front[k]]
            extent = float(np.linalg.norm(pts[:, mine] - P[:, None], axis=0).max())
            ro = max(0.125 * extent, 2 * hs[k]) if r_out is None else r_out
            if ro < hs[k]:
                raise InputError(f"r_out = {ro:.3g} at front node {int(it.front[k])} spans less than one element "
                                 f"({hs[k]:.3g})")
            K[k] = _node_integral(body, geo, it, frames[k], P, ro)
            radius[k] = ro
    return StressIntensity(3, it.front.copy(), pts[:, it.front].T.copy(), it.front_id.copy(), K[:, 0], K[:, 1],
                           K[:, 2], frames, "interaction", radius)


#: the 4-point rule on a tetrahedron (exact for quadratics): barycentric (A, B, B, B) and its permutations, weights 1/4
_TET4 = np.full((4, 4), 0.1381966011250105) + np.eye(4) * (0.5854101966249685 - 0.1381966011250105)
#: the corners of the mid-edge nodes 4..9 of a quadratic tetrahedron (VTK's tetra10 order, as GeometryPart holds them)
_EDGES10 = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))


def _p2_gradients(pts: np.ndarray, cells: np.ndarray, u: np.ndarray, grad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The displacement gradients (4 nt, 3, 3) (d u_c / d x_d) of the quadratic tetrahedra ``cells`` (10, nt) at the
    4 points of :data:`_TET4` (point k of tetrahedron t at 4 t + k) and the points (3, 4 nt); ``grad`` (4, 3, nt)
    the corners' barycentric gradients (straight-sided tetrahedra: N_i = l_i (2 l_i - 1), N_ij = 4 l_i l_j)."""
    nt = cells.shape[1]
    D, X = np.empty((nt, 4, 3, 3)), np.empty((3, nt, 4))
    for k, lam in enumerate(_TET4):
        gN = np.empty((10, 3, nt))
        for i in range(4):
            gN[i] = (4 * lam[i] - 1) * grad[i]
        for e, (i, j) in enumerate(_EDGES10):
            gN[4 + e] = 4 * (lam[i] * grad[j] + lam[j] * grad[i])
        D[:, k] = np.einsum("tic,idt->tcd", u[cells.T], gN)
        X[:, :, k] = np.einsum("dit,i->dt", pts[:, cells[:4]], lam)
    return D.reshape(4 * nt, 3, 3), X.reshape(3, 4 * nt)


class _Body:
    """The FE fields of the body (global frame) at its integration points (``npt`` per tetrahedron: point k of
    tetrahedron t at ``npt t + k``; ``xq`` their positions, ``vol`` their weights) and what the integral needs
    besides; ``grad`` the corners' barycentric gradients per tetrahedron (q is P1 on the corners)."""

    def __init__(self, pts, tets, grad, vol, Du, eps, sig, traction, G, nu, xq, npt):
        self.pts, self.tets, self.grad, self.vol, self.Du, self.eps, self.sig = pts, tets, grad, vol, Du, eps, sig
        self.traction, self.G, self.nu, self.xq, self.npt = traction, G, nu, xq, npt
        self.node_tets = node_cells(tets, pts.shape[1])
        from scipy.spatial import cKDTree

        self.tree = cKDTree(pts.T)
        self.q = np.zeros(pts.shape[1])                 # the weight of the current front node (reset after it)


class _FrontGeometry:
    """Distances to one defect's front (a polyline of its edges) of nodes, integration points ``xq`` and the face
    rule's points, each computed on first use and kept (they do not depend on the front node)."""

    def __init__(self, it, pts, xq, edges):
        self.it, self.pts, self.xq, self.A, self.B = it, pts, xq, pts[:, edges[:, 0]], pts[:, edges[:, 1]]
        self.edges = edges
        self.r_node, self.foot_node = np.full(pts.shape[1], np.nan), np.zeros((3, pts.shape[1]))
        self.r_tet, self.foot_tet = np.full(xq.shape[1], np.nan), np.zeros((3, xq.shape[1]))
        self.face_cache: dict[int, tuple] = {}

    def _fill(self, ids, r, foot, points):
        todo = ids[np.isnan(r[ids])]
        if todo.size:
            r[todo], foot[:, todo] = distance_to_front(points(todo), self.A, self.B)
        return r[ids], foot[:, ids]

    def nodes(self, ids):
        return self._fill(ids, self.r_node, self.foot_node, lambda i: self.pts[:, i])

    def points(self, ids):
        return self._fill(ids, self.r_tet, self.foot_tet, lambda i: self.xq[:, i])

    def faces(self):
        """The face rule of the defect's triangles (:func:`_face_rule`), computed once."""
        if not self.face_cache:
            self.face_cache[0] = _face_rule(self.it, self.pts, self.edges)
        return self.face_cache[0]


def _node_integral(body: _Body, geo: _FrontGeometry, it, F: np.ndarray, P: np.ndarray, ro: float) -> np.ndarray:
    """(K_I, K_II, K_III) at the front node at P with frame F (rows e1, e2, e3) and domain radius ro."""
    tets, q = body.tets, body.q
    near = np.asarray(body.tree.query_ball_point(P, 1.5 * ro), dtype=np.int64)
    r_n, foot = geo.nodes(near)
    q[near] = np.clip(1 - r_n / ro, 0, 1) * np.clip(1 - np.abs(F[2] @ (foot - P[:, None])) / ro, 0, 1)
    e = geo.edges
    length = float(np.sum(0.5 * (q[e[:, 0]] + q[e[:, 1]]) * np.linalg.norm(geo.B - geo.A, axis=0)))
    if length <= 0:
        q[near] = 0.0
        raise InputError(f"the domain of the front node at {P.round(6).tolist()} holds no front")
    T = np.unique(np.concatenate([body.node_tets[n] for n in near[q[near] > 0]]))
    gq = np.einsum("it,idt->td", q[tets[:, T]], body.grad[:, :, T]) @ F.T                  # grad q, tip frame
    Q = (T[:, None] * body.npt + np.arange(body.npt)).ravel()                              # their points
    gq = np.repeat(gq, body.npt, axis=0)
    rc, fc = geo.points(Q)
    dv = F @ (body.xq[:, Q] - fc)
    th = np.arctan2(dv[1], dv[0])
    S, D, Ep = (F @ f[Q] @ F.T for f in (body.sig, body.Du, body.eps))          # FE fields in the tip frame
    faces = _face_points(geo.faces(), it, q, body.traction, F) if body.traction is not None else None
    K = np.zeros(3)
    for mode in (1, 2, 3):
        Sa, Ua = _aux(np.maximum(rc, 1e-300), th, mode, body.G, body.nu)
        integrand = (Ua[:, None, :] @ S)[:, 0] + (D[:, None, :, 0] @ Sa)[:, 0]
        integrand[:, 0] -= (Sa * Ep).sum(axis=(1, 2))
        I = float(body.vol[Q] @ (integrand * gq).sum(axis=1))
        if faces is not None:
            wq, rq, tq, side = faces
            c = np.stack([_aux(np.ones(1), np.array([sd * np.pi]), mode, body.G, body.nu)[1][0] for sd in (1.0, -1.0)])
            I -= float(np.sum(wq / np.sqrt(rq) * np.einsum("fpi,fi->fp", tq, c[np.where(side > 0, 0, 1)])))
        E = 2 * body.G * (1 + body.nu)
        K[mode - 1] = I / length * (E / (1 - body.nu ** 2) / 2 if mode < 3 else body.G)
    q[near] = 0.0
    return K


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


def _face_rule(it, pts: np.ndarray, edges: np.ndarray):
    """The face integral's quadrature on the defect triangles that touch the front's defect (both faces share it):
    the triangles' node ids of the "-" face and of the "+" face (faces, 3), sorted so that V2 is the vertex
    farthest from the front, which vertices are front nodes (faces, 3), the barycentric coordinates of the
    points (16, 3), their weights x Jacobian (faces, 16) and their distances to the front (faces, 16).

    Each triangle is mapped from V2, ``x = V2 + sigma (V0 + tau (V1 - V0) - V2)``, with ``sigma = 1 - rho^2``
    so that the r^-1/2 of the auxiliary fields at the edge nearest the front is integrated exactly enough by
    Gauss points in (rho, tau)."""
    front = np.unique(edges)
    f = it.faces[np.isin(it.faces, front).any(axis=1) | np.isin(it.faces, _defect_nodes(it, front)).all(axis=1)]
    is_front = np.isin(f, it.front)
    f, is_front = f[~is_front.all(axis=1)], is_front[~is_front.all(axis=1)]
    if f.size == 0:
        return None
    A, B = pts[:, edges[:, 0]], pts[:, edges[:, 1]]
    r_v, _ = distance_to_front(pts[:, f.ravel()], A, B)
    order = np.argsort(r_v.reshape(f.shape), axis=1)                    # V0, V1 nearest the front, V2 farthest
    f, is_front = np.take_along_axis(f, order, axis=1), np.take_along_axis(is_front, order, axis=1)
    rho2, tau2 = np.meshgrid(_G4X, _G4X, indexing="ij")
    sig, tau = (1 - rho2 ** 2).ravel(), tau2.ravel()
    lam = np.stack([sig * (1 - tau), sig * tau, 1 - sig], axis=1)       # barycentric of V0, V1, V2 (16, 3)
    V = pts[:, f]                                                        # (3, faces, 3)
    area2 = np.linalg.norm(np.cross((V[:, :, 1] - V[:, :, 0]).T, (V[:, :, 2] - V[:, :, 0]).T), axis=1)
    rq, _ = distance_to_front(np.einsum("kfa,pa->kfp", V, lam).reshape(3, -1), A, B)
    # dA = 2 A sigma dsigma dtau and dsigma = 2 rho drho
    jacw = area2[:, None] * (sig * 2 * np.sqrt(1 - sig) * np.outer(_G4W, _G4W).ravel())[None, :]
    plus = np.arange(pts.shape[1])
    plus[it.lower] = it.upper
    return f, plus[f], is_front, lam, jacw, rq.reshape(len(f), -1)


def _defect_nodes(it, front: np.ndarray) -> np.ndarray:
    """The "-" copies of the defect whose front holds the nodes ``front``."""
    d = np.unique(it.front_id[np.isin(it.front, front)])
    return it.lower[np.isin(it.defect_id, d)]


def _face_points(rule, it, q: np.ndarray, traction: np.ndarray, F: np.ndarray):
    """The face integral's points of the triangles with q > 0 (:func:`_face_rule`) on both faces: weights x q
    (n, 16), r (n, 16), tractions in the tip frame (n, 16, 3) and the side (n,) (+1: the face e2 points to); q
    and the traction linear on each triangle (a front vertex takes the mean traction of the triangle's others)."""
    if rule is None:
        return None
    f_minus, f_plus, is_front, lam, jacw, rq = rule
    sel = np.flatnonzero((q[f_minus] > 0).any(axis=1))
    if sel.size == 0:
        return None
    out = []
    for ids in (f_minus[sel], f_plus[sel]):
        fr = is_front[sel]
        T = (F @ traction[:, ids.ravel()]).T.reshape(*ids.shape, 3)     # (faces, 3 vertices, 3)
        mean = (T * ~fr[:, :, None]).sum(axis=1) / np.maximum((~fr).sum(axis=1), 1)[:, None]
        T = np.where(fr[:, :, None], mean[:, None, :], T)
        tq = np.einsum("fai,pa->fpi", T * q[ids][:, :, None], lam)
        side = _side(it, ids[np.arange(len(ids)), np.argmax(~fr, axis=1)], F[1])
        out.append((jacw[sel], rq[sel], tq, side))
    return tuple(np.concatenate([o[i] for o in out]) for i in range(4))


