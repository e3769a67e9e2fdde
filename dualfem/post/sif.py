"""Stress intensity factors at 2D crack tips and along 3D crack fronts: the result type, the tip frames and the
displacement-correlation estimate (the interaction integrals, measured against it: :mod:`dualfem.post.sif_integral`
in 2D, :mod:`dualfem.post.sif_integral3d` in 3D; the choice and the outputs: :mod:`dualfem.post.sif_outputs`).

Everything is computed from a solution's unknowns ``x`` and the QP's typed parts: the interface
(:class:`~dualfem.core.parts.InterfacePart`: ``front``/``front_id``, ``normals``, ``tangents``, ``faces``,
:meth:`jumps`), the mesh (``geometry``: ``nodes``, ``cells``) and the material (``material``: ``E``, ``nu``,
``plane``). Units: stress x sqrt(length) (MPa sqrt(m) for a scene in MPa and m).

Conventions (the Williams fields of a straight front, Irwin's modes):

* At a tip (2D) or front node (3D) the local frame is right-handed: ``e1`` the direction of travel of the
  crack toward the tip (in the crack's plane, pointing into the ligament ahead), ``e2`` normal to the crack
  with ``(e1, e2)`` right-handed in 2D (``e2`` = ``e1`` turned by +90 degrees) and ``e2`` = the interface's
  unit normal (the "+" side) in 3D, ``e3 = e1 x e2`` tangent to the front (3D). The "upper" face is the one
  ``e2`` points to, the jump ``[u] = u(upper) - u(lower)``; in 2D the upper face is the "+" face at the last
  tip of a defect and the "-" face at its first tip, so both tips of a straight crack under the same load get
  the same K_I and K_II (a centre crack under shear ``sigma_12 = tau``: K_II = tau sqrt(pi a) at both).
* Behind the front at distance r, with the shear modulus ``G`` and Kolosov's ``kappa`` (3 - 4 nu: plane
  strain and 3D; (3 - nu)/(1 + nu): plane stress)::

      [u . e2] = (kappa + 1)/G K_I  sqrt(r / (2 pi))      (opening: K_I >= 0 for an open crack)
      [u . e1] = (kappa + 1)/G K_II sqrt(r / (2 pi))      (sliding along the direction of travel)
      [u . e3] = 4/G K_III sqrt(r / (2 pi))               (tearing, 3D)

  so K_I and K_II are those of Irwin's convention; K_III's sign follows ``e3 = e1 x e2`` (a penny
  crack under shear along x: K_III = +4 (1 - nu) tau sqrt(a/pi) sin(theta)/(2 - nu) at the front point
  of polar angle theta about the normal; with the tangent taken counterclockwise, -e3, the sign flips).
* Displacement correlation (``method="fit"``): the jumps at the defect nodes within ``rings`` tip element
  sizes behind the tip are fitted by ``c sqrt(r)`` (least squares) and K read from c;
  ``method="extrapolate"``: the pointwise K(r) of the same nodes is extrapolated linearly to r -> 0. A closed
  crack has no normal jump: its K_I is 0, its K_II comes from the slip.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from dualfem.core.errors import InputError

#: the displacement-correlation variants of :func:`correlation`
METHODS = ("fit", "extrapolate")


@dataclass(frozen=True)
class StressIntensity:
    """Stress intensity factors at k front points (2D: the tips; 3D: the front nodes), one row each.

    ``node`` (k,): mesh node ids; ``point`` (k, dim): their coordinates; ``defect`` (k,): their defect;
    ``K_I``, ``K_II`` (k,), ``K_III`` (k,) in 3D (None in 2D), stress x sqrt(length), the module's sign
    conventions; ``frame`` (k, dim, dim): rows e1, e2 (, e3) of the tip frame; ``method``: how they were
    computed; ``radius`` (k,): the distance over which the jumps or fields were used (length)."""

    dim: int
    node: np.ndarray
    point: np.ndarray
    defect: np.ndarray
    K_I: np.ndarray
    K_II: np.ndarray
    K_III: np.ndarray | None
    frame: np.ndarray
    method: str
    radius: np.ndarray

    def to_json(self) -> dict:
        """A JSON-ready dict: the method and one list per field (``K_III`` only in 3D)."""
        out = {"method": self.method, "node": self.node.tolist(), "defect": self.defect.tolist(),
               "point": np.round(self.point, 12).tolist(), "K_I": self.K_I.tolist(), "K_II": self.K_II.tolist(),
               "radius": self.radius.tolist()}
        if self.K_III is not None:
            out["K_III"] = self.K_III.tolist()
        return out


def kolosov(nu: float, plane: str, dim: int) -> float:
    """Kolosov's kappa: 3 - 4 nu (plane strain, 3D), (3 - nu)/(1 + nu) (plane stress)."""
    return (3 - nu) / (1 + nu) if dim == 2 and plane == "stress" else 3 - 4 * nu


def parts(qp, elements: tuple[str, ...] = ("P1",)):
    """(interface, geometry, material) of the QP; InputError naming what is missing, or when its element
    (``geometry.element``) is not one of ``elements``."""
    for k in ("interface", "geometry", "material"):
        if getattr(qp, k, None) is None:
            raise InputError(f"stress intensity factors need the QP's {k} part (build the QP from a scene)")
    it = tips_only(qp.interface)
    if it.front.size == 0:
        raise InputError("stress intensity factors need crack tips or fronts (interface.front is empty, or holds "
                         "only the mouths of edge cracks)")
    if qp.geometry.element not in elements:
        raise InputError(f"stress intensity factors by this method need element = {' or '.join(map(repr, elements))}; "
                         f"this QP has element = {qp.geometry.element!r} (--sif takes element = 'P1', "
                         f"'P2-quarter-point' in 2D and 'P2' in 3D)")
    return it, qp.geometry, qp.material


def tips_only(it):
    """The interface with its front cut to the crack tips (2D) or front nodes (3D) inside the body: a front entry
    that is a doubled node (in ``lower`` or ``upper``) is where a crack meets the body's boundary (an edge crack's
    mouth: a body from a file lists it as a chain end), no tip, so no stress intensity factor there."""
    mouth = np.isin(it.front, np.r_[it.lower, it.upper])
    if not mouth.any():
        return it
    return replace(it, front=it.front[~mouth], front_id=it.front_id[~mouth])


def check_x(qp, x) -> np.ndarray:
    """The unknowns as a float vector of length ``qp.n`` (InputError otherwise)."""
    x = np.asarray(x, dtype=float)
    if x.shape != (qp.n,) or not np.all(np.isfinite(x)):
        raise InputError(f"x must be {qp.n} finite numbers (the QP's unknowns), got shape {x.shape}")
    if qp.shift is not None:
        x = x + qp.shift.x
    return x


def _rows_of_tip(it, pts: np.ndarray, k: int) -> np.ndarray:
    """2D: the interface rows of tip k's defect that are nearer to tip k than to the defect's other tip."""
    d = it.front_id[k]
    rows = np.flatnonzero(it.defect_id == d)
    tips = np.flatnonzero(it.front_id == d)
    X = pts[:, it.lower[rows]]
    dist = np.stack([np.hypot(*(X - pts[:, it.front[t]][:, None])) for t in tips])
    return rows[np.argmin(dist, axis=0) == int(np.flatnonzero(tips == k)[0])]


def tip_frames_2d(it, pts: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """The frames (k, 2, 2) (rows e1, e2) of the 2D tips and, per tip, its defect rows (nearest first)."""
    frames, rows = [], []
    for k, tip in enumerate(it.front):
        r = _rows_of_tip(it, pts, k)
        if r.size == 0:
            raise InputError(f"tip {k} (node {int(tip)}) has no defect node behind it")
        dist = np.hypot(*(pts[:, it.lower[r]] - pts[:, tip][:, None]))
        r = r[np.argsort(dist)]
        t = it.tangents[r[0], 0]
        e1 = t if t @ (pts[:, tip] - pts[:, it.lower[r[0]]]) > 0 else -t
        frames.append(np.array([e1, [-e1[1], e1[0]]]))
        rows.append(r)
    return np.array(frames), rows


def _front_edges(it, d: int) -> np.ndarray:
    """(n_edges, 2) node ids of the front edges of defect d (edges of its faces with both ends on the front)."""
    if it.faces is None or it.faces.size == 0:
        return np.zeros((0, 2), np.int64)
    front = it.front[it.front_id == d]
    on = np.isin(it.faces, front)
    e = np.concatenate([it.faces[:, [0, 1]], it.faces[:, [1, 2]], it.faces[:, [2, 0]]])
    keep = np.concatenate([on[:, 0] & on[:, 1], on[:, 1] & on[:, 2], on[:, 2] & on[:, 0]])
    return np.unique(np.sort(e[keep], axis=1), axis=0)


def node_cells(cells: np.ndarray, n_nodes: int) -> list[np.ndarray]:
    """For every node, the cells (columns of ``cells``) that hold it."""
    t = np.repeat(np.arange(cells.shape[1]), cells.shape[0])
    n = cells.T.ravel()
    order = np.argsort(n, kind="stable")
    return np.split(t[order], np.cumsum(np.bincount(n, minlength=n_nodes))[:-1])


def distance_to_front(X: np.ndarray, A: np.ndarray, B: np.ndarray, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Distance of the points X (3, p) to the polyline of segments A -> B (3, s), and the nearest points (3, p):
    each point's nearest among the k segments whose midpoints are nearest to it (all of them when s <= k; a
    front's edges are of comparable lengths, so its nearest segment is among them)."""
    s = A.shape[1]
    if s > k:
        from scipy.spatial import cKDTree

        _, idx = cKDTree((0.5 * (A + B)).T).query(X.T, k=k)               # (p, k)
    else:
        idx = np.broadcast_to(np.arange(s), (X.shape[1], s))
    a, ab = A[:, idx], (B - A)[:, idx]                                      # (3, p, k)
    t = np.einsum("kpj,kpj->pj", X[:, :, None] - a, ab) / np.maximum(np.einsum("kpj,kpj->pj", ab, ab), 1e-300)
    foot = a + np.clip(t, 0.0, 1.0)[None] * ab
    d = np.linalg.norm(X[:, :, None] - foot, axis=0)
    j = np.argmin(d, axis=1)
    p = np.arange(X.shape[1])
    return d[p, j], foot[:, p, j]


def _frame_3d(it, pts: np.ndarray, k: int, rows: np.ndarray, edges: np.ndarray, h: float) -> np.ndarray:
    """Rows e1, e2, e3 at front node k: e2 the mean unit normal of the defect nodes within 2 h, e3 along the
    front (its neighbours on the front edges, else the nearest front nodes), e1 = e2 x e3 pointing away from
    the crack, then e3 = e1 x e2."""
    P = pts[:, it.front[k]]
    X = pts[:, it.lower[rows]]
    dist = np.linalg.norm(X - P[:, None], axis=0)
    near = dist <= 2 * dist.min() + 1e-12 * h
    n = it.normals[rows[near]].sum(axis=0)
    n /= np.linalg.norm(n)
    nb = edges[np.any(edges == it.front[k], axis=1)].ravel()
    nb = nb[nb != it.front[k]]
    if nb.size < 1:
        same = it.front[(it.front_id == it.front_id[k]) & (it.front != it.front[k])]
        dd = np.linalg.norm(pts[:, same] - P[:, None], axis=0)
        nb = same[np.argsort(dd)[:2]]
    if nb.size == 0:
        raise InputError(f"front node {int(it.front[k])} has no neighbour on its front: no front direction")
    tau = pts[:, nb[-1]] - (pts[:, nb[0]] if nb.size > 1 else P)
    tau -= (tau @ n) * n
    e1 = np.cross(tau, n)
    e1 /= np.linalg.norm(e1)
    if e1 @ (P - X[:, near].mean(axis=1)) < 0:
        e1 = -e1
    return np.array([e1, n, np.cross(e1, n)])


def front_frames_3d(it, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[int, np.ndarray]]:
    """3D: the frames (k, 3, 3) (rows e1, e2, e3) of the front nodes, their element sizes h (k,) (the distance to
    the nearest defect node) and each defect's front edges (:func:`_front_edges`)."""
    edges = {int(d): _front_edges(it, int(d)) for d in np.unique(it.front_id)}
    frames, hs = [], []
    for k, tip in enumerate(it.front):
        d = int(it.front_id[k])
        rows = np.flatnonzero(it.defect_id == d)
        h = float(np.linalg.norm(pts[:, it.lower[rows]] - pts[:, tip][:, None], axis=0).min())
        frames.append(_frame_3d(it, pts, k, rows, edges[d], h))
        hs.append(h)
    return np.array(frames).reshape(-1, 3, 3), np.array(hs), edges


def correlation(qp, x, method: str = "fit", rings: float = 4.0) -> StressIntensity:
    """K_I, K_II (and K_III in 3D) by displacement correlation (module docstring): the defect nodes within
    ``rings`` element sizes (the distance from the tip to its nearest defect node) behind each tip or front node
    (3D: whose nearest point on the front lies within one element of the node) fitted by ``c sqrt(r)``
    (``method="fit"``) or their pointwise K(r) extrapolated linearly to r = 0 (``"extrapolate"``)."""
    if method not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if not (isinstance(rings, (int, float)) and 1.0 <= rings <= 100.0):
        raise InputError(f"rings must be a number in [1, 100] (element sizes behind the tip), got {rings!r}")
    it, g, mat = parts(qp)
    x = check_x(qp, x)
    pts = g.nodes
    G = mat.E / (2 * (1 + mat.nu))
    kappa = kolosov(mat.nu, mat.plane, it.dim)
    coef = np.array([G / (kappa + 1), G / (kappa + 1), G / 4.0])[:it.dim] * np.sqrt(2 * np.pi)   # e1, e2, e3
    jump = x[it.plus_dofs] - x[it.minus_dofs]                      # (m, dim): [u] = u+ - u-
    if it.dim == 2:
        frames, tip_rows = tip_frames_2d(it, pts)
    else:
        frames, hs, edges = front_frames_3d(it, pts)
    K, radius = np.zeros((it.front.size, it.dim)), np.zeros(it.front.size)
    for k, tip in enumerate(it.front):
        P = pts[:, tip]
        if it.dim == 2:
            rows, F = tip_rows[k], frames[k]
            r = np.hypot(*(pts[:, it.lower[rows]] - P[:, None]))
            h = r.min()
        else:
            d, F, h = int(it.front_id[k]), frames[k], hs[k]
            rows = np.flatnonzero(it.defect_id == d)
            X = pts[:, it.lower[rows]]
            dist = np.linalg.norm(X - P[:, None], axis=0)
            cand = dist <= (rings + 2) * h
            rows, X = rows[cand], X[:, cand]
            e = edges[d]
            if e.size:
                r, foot = distance_to_front(X, pts[:, e[:, 0]], pts[:, e[:, 1]])
            else:
                r, foot = np.linalg.norm(X - P[:, None], axis=0), np.repeat(P[:, None], X.shape[1], axis=1)
            keep = np.linalg.norm(foot - P[:, None], axis=0) <= h * (1 + 1e-9)
            rows, r = rows[keep], r[keep]
        use = r <= rings * h * (1 + 1e-9)
        if use.sum() < 2:
            use = np.argsort(r)[:2]
        rows, r = rows[use], r[use]
        side = np.sign(np.einsum("jk,k->j", it.normals[rows], F[1]))
        J = side[:, None] * (jump[rows] @ F.T)                     # (p, dim): jumps in the tip frame
        if method == "fit":
            K[k] = coef * (np.sqrt(r) @ J) / r.sum()
        elif r.size >= 2 and np.ptp(r) > 0:
            A = np.stack([np.ones_like(r), r], axis=1)
            K[k] = np.linalg.lstsq(A, J / np.sqrt(r)[:, None], rcond=None)[0][0] * coef
        else:
            K[k] = coef * J.mean(axis=0) / np.sqrt(r.mean())
        radius[k] = r.max()
    return StressIntensity(it.dim, it.front.copy(), pts[:, it.front].T.copy(), it.front_id.copy(), K[:, 1].copy(),
                           K[:, 0].copy(), K[:, 2].copy() if it.dim == 3 else None, frames,
                           f"correlation-{method}", radius)
