"""Post-processing of a thin-defect solution: nodal displacements, strains and stresses per
triangle, von Mises stress, fields along the defect, deformed coordinates.

Everything is computed from the QP's mesh (``qp.geometry``: ``nodes``, ``cells``, ``node_dofs``),
its defect interface (``qp.interface``: node pairs, normals and tangents, tips, arc length ``s``;
:class:`~dualfem.core.parts.InterfacePart`) and its material (``qp.material``: ``E``, ``nu``, ``plane``), so a QP
built by a scene is enough; a QP read back from a file may pass ``E``, ``nu``, ``plane`` explicitly.
Nothing is computed until asked for: :class:`Post` evaluates each field on first access and
caches it.

Conventions:

* P1 elements: strains and stresses are constant per triangle (Voigt order 11, 22, 12; the
  engineering shear ``gamma12 = 2 eps12`` is *not* used: ``eps12`` is the tensor component).
* Stress in the units of ``E`` (MPa for the paper's scenes). Plane strain: ``sigma33 =
  lambda (eps11 + eps22)``; plane stress: ``sigma33 = 0`` and ``lambda`` is replaced by
  ``lambda* = 2 lambda mu / (lambda + 2 mu)`` (see :func:`dualfem.core.elasticity.lame`). The von
  Mises stress always uses all three normal components.
* Along the defect the coordinate ``s`` runs from the first tip (s = 0) to the second; the
  tips are single (not doubled) nodes, so the jump is zero there. ``jump_normal = [u.nu] =
  (u+ - u-).nu`` ("+" = the face the normal points to, the upper face for the default scene),
  ``jump_tangent = (u+ - u-).tau``. ``pressure = mu / w`` (the paper's ``l = -sigma_nu +
  [u_nu]/delta``, units of stress), ``force = mu`` (nodal contact forces).
"""
from __future__ import annotations

from functools import cached_property

import numpy as np

from dualfem.core.elasticity import lame
from dualfem.core.errors import InputError
from dualfem.core.parts import GeometryPart


def _geometry(qp) -> GeometryPart:
    """The QP's mesh (``qp.geometry``); InputError if it has none."""
    if getattr(qp, "geometry", None) is None:
        raise InputError("post-processing needs the mesh of the QP (qp.geometry: nodes, cells, node_dofs): "
                         "build the QP from a scene (or export it with its map_ arrays)")
    return qp.geometry


def material(qp, E: float | None = None, nu: float | None = None, plane: str | None = None) -> tuple[float, float, str]:
    """(E, nu, plane) from the arguments, else from ``qp.material``; InputError if unknown."""
    mat = getattr(qp, "material", None)
    E = (mat.E if mat else None) if E is None else E
    nu = (mat.nu if mat else None) if nu is None else nu
    plane = (mat.plane if mat else "strain") if plane is None else plane
    if E is None or nu is None:
        raise InputError("post-processing needs the material: pass E and nu (the QP has no material part)")
    if plane not in ("strain", "stress"):
        raise InputError(f"plane must be 'strain' or 'stress', got {plane!r}")
    return float(E), float(nu), str(plane)


def nodal_displacement(qp, x: np.ndarray) -> np.ndarray:
    """Displacement of every mesh node, shape (nnodes, 2); clamped components are 0.

    A QP whose unknowns are shifted (``qp.shift``: the displacement is ``x + shift.x``, e.g. the
    Signorini problem) is shifted back here.
    """
    nd = _geometry(qp).node_dofs
    x = np.asarray(x, dtype=float)
    if x.shape != (qp.n,):
        raise InputError(f"x must have length {qp.n}, got shape {x.shape}")
    if qp.shift is not None:
        x = x + qp.shift.x
    u = np.zeros(nd.shape[::-1])
    mask = nd >= 0
    u.T[mask] = x[nd[mask]]
    return u


def free_vector(qp, u: np.ndarray) -> np.ndarray:
    """Inverse of :func:`nodal_displacement`: the vector x of free unknowns from nodal values."""
    nd = _geometry(qp).node_dofs
    x = np.zeros(qp.n)
    mask = nd >= 0
    x[nd[mask]] = np.asarray(u).T[mask]
    return x if qp.shift is None else x - qp.shift.x


def shape_gradients(nodes: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of the three P1 basis functions per triangle, shape (ntri, 3, 2), and areas."""
    p = np.asarray(nodes)[:, np.asarray(tri)]  # (2, 3, ntri)
    x, y = p[0], p[1]
    # d(lambda_i)/dx = (y_j - y_k) / (2A), d/dy = (x_k - x_j) / (2A), (i, j, k) cyclic
    twoA = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])
    if np.any(np.abs(twoA) <= 0):
        raise InputError("mesh has a degenerate triangle")
    j, k = [1, 2, 0], [2, 0, 1]
    gx = (y[j] - y[k]) / twoA
    gy = (x[k] - x[j]) / twoA
    return np.stack([gx.T, gy.T], axis=2), 0.5 * np.abs(twoA)


def strains(qp, x: np.ndarray) -> np.ndarray:
    """Strain per triangle, shape (ntri, 3): eps11, eps22, eps12 (tensor shear)."""
    g = _geometry(qp)
    tri = g.cells
    grad, _ = shape_gradients(g.nodes, tri)
    u = nodal_displacement(qp, x)[tri.T]  # (ntri, 3, 2)
    du = np.einsum("tic,tid->tcd", u, grad)  # du[t, c, d] = d u_c / d x_d
    return np.stack([du[:, 0, 0], du[:, 1, 1], 0.5 * (du[:, 0, 1] + du[:, 1, 0])], axis=1)


def stresses(qp, x: np.ndarray, E: float | None = None, nu: float | None = None,
             plane: str | None = None) -> dict[str, np.ndarray]:
    """Stress per triangle: ``s11, s22, s12, s33`` and ``von_mises`` (units of E)."""
    E, nu, plane = material(qp, E, nu, plane)
    lam, mu = lame(E, nu, plane)
    eps = strains(qp, x)
    tr = eps[:, 0] + eps[:, 1]
    s11 = lam * tr + 2 * mu * eps[:, 0]
    s22 = lam * tr + 2 * mu * eps[:, 1]
    s12 = 2 * mu * eps[:, 2]
    s33 = lam * tr if plane == "strain" else np.zeros_like(tr)
    return {"s11": s11, "s22": s22, "s12": s12, "s33": s33, "von_mises": von_mises(s11, s22, s12, s33)}


def von_mises(s11, s22, s12, s33=0.0) -> np.ndarray:
    """sqrt(1/2 [(s11-s22)^2 + (s22-s33)^2 + (s33-s11)^2] + 3 s12^2)."""
    s11, s22, s12, s33 = (np.asarray(a, dtype=float) for a in (s11, s22, s12, s33))
    return np.sqrt(0.5 * ((s11 - s22) ** 2 + (s22 - s33) ** 2 + (s33 - s11) ** 2) + 3 * s12 ** 2)


def deformed_nodes(qp, x: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Node coordinates of the deformed body, ``X + scale * u``, shape (2, nnodes)."""
    return _geometry(qp).nodes + scale * nodal_displacement(qp, x).T


def _defect_pieces(it, nodes: np.ndarray):
    """Per defect: (id, rows of B in order, first tip, last tip, its length) from the interface part
    (:class:`~dualfem.core.parts.InterfacePart`: its ``front`` holds two tips per defect in 2D); the tips
    are None when the part does not give them (one entry for every defect then)."""
    tips, ids, lo = it.front, it.defect_id, it.lower
    ndef = int(ids.max()) + 1 if ids.size else 0
    if tips.size != 2 * ndef:
        return [(0, np.arange(it.m), None, None, None)]
    out = []
    for k in range(ndef):
        rows = np.flatnonzero(ids == k)
        t0, t1 = tips[2 * k], tips[2 * k + 1]
        # arc length (kinked, curved): the last interior node's s + its last edge
        L = float(it.s[rows[-1]] + np.linalg.norm(nodes[:, t1] - nodes[:, lo[rows[-1]]]))
        out.append((k, rows, t0, t1, L))
    return out


def defect_fields(qp, x: np.ndarray, multipliers: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Fields along the defects, defect by defect, each ordered by its coordinate ``s``.

    Node arrays with each defect's two tips included (first and last entry of its stretch):
    ``s`` (from the defect's first tip), ``X`` (2, k) reference positions, ``upper``/``lower``
    node ids (the tip id on both), ``defect_id``, ``row`` (row of B, -1 at a tip), ``u_upper``,
    ``u_lower`` (k, 2), ``normal``/``tangent`` (k, 2; a tip takes its neighbour's),
    ``jump_normal``, ``jump_tangent`` (0 at the tips), ``pressure`` and ``force`` (NaN at the
    tips, which carry no constraint; only when ``multipliers`` given). ``interior`` is a boolean
    mask of the constrained (doubled) nodes. :func:`defect_stretches` splits the arrays by defect.
    Read from ``qp.interface`` (a 2D :class:`~dualfem.core.parts.InterfacePart` with its arc length ``s``).
    """
    it = getattr(qp, "interface", None)
    nodes = _geometry(qp).nodes
    if it is None or it.dim != 2 or it.s is None:
        raise InputError("post-processing of the defect needs qp.interface, a 2D interface part with its arc "
                         "length s (a QP file: map_defect_upper, map_defect_lower and map_defect_s)")
    up, lo, s_in = it.upper, it.lower, it.s
    nrm_j, tau_j = it.normals, it.tangents[:, 0, :]
    parts: dict[str, list] = {k: [] for k in ("s", "upper", "lower", "row", "id", "nrm", "tau")}
    for k, rows, t0, t1, L in _defect_pieces(it, nodes):
        # the tips: no row of B, the normal of their neighbour; an end that is a doubled node (an edge
        # crack's mouth, given as its "-" copy) is a row already
        head = [t0] if t0 is not None and t0 not in lo[rows] else []
        tail = [t1] if t1 is not None and t1 not in lo[rows] else []
        row = np.r_[[-1] * len(head), rows, [-1] * len(tail)].astype(np.int64)
        near = np.r_[rows[:1].repeat(len(head)), rows, rows[-1:].repeat(len(tail))]
        parts["s"].append(np.r_[[0.0] * len(head), s_in[rows], [L] * len(tail)])
        parts["upper"].append(np.r_[head, up[rows], tail].astype(np.int64))
        parts["lower"].append(np.r_[head, lo[rows], tail].astype(np.int64))
        parts["row"].append(row)
        parts["id"].append(np.full(row.size, k, dtype=np.int64))
        parts["nrm"].append(nrm_j[near])
        parts["tau"].append(tau_j[near])
    if not parts["s"]:          # no defect (defects = []): every field empty
        parts = {k: [np.zeros(0, float if k == "s" else np.int64)] for k in ("s", "upper", "lower", "row", "id")} | \
            {k: [np.zeros((0, 2))] for k in ("nrm", "tau")}
    s, upper, lower, row, did = (np.concatenate(parts[k]) for k in ("s", "upper", "lower", "row", "id"))
    nrm_n, tau_n = np.vstack(parts["nrm"]), np.vstack(parts["tau"])
    interior = row >= 0
    u = nodal_displacement(qp, x)
    uu, ul = u[upper], u[lower]
    d = uu - ul
    out = {"s": s, "X": nodes[:, lower], "upper": upper, "lower": lower, "interior": interior,
           "defect_id": did, "row": row, "normal": nrm_n, "tangent": tau_n,
           "u_upper": uu, "u_lower": ul, "jump_normal": np.sum(d * nrm_n, axis=1),
           "jump_tangent": np.sum(d * tau_n, axis=1)}
    if multipliers is not None:
        mu = np.asarray(multipliers, dtype=float)
        if mu.shape != (qp.m,):
            raise InputError(f"multipliers must have length {qp.m}, got shape {mu.shape}")
        force = np.full(s.size, np.nan)
        press = np.full(s.size, np.nan)
        force[interior] = mu[row[interior]]
        press[interior] = qp.pressure(mu)[row[interior]]
        out["force"] = force
        out["pressure"] = press
    return out


def defect_stretches(fields: dict[str, np.ndarray]) -> list[np.ndarray]:
    """Index arrays into :func:`defect_fields` output, one per defect (tips included), in defect order."""
    did = np.asarray(fields["defect_id"])
    return [np.flatnonzero(did == k) for k in np.unique(did)]


def contact_length(s: np.ndarray, jump: np.ndarray, tol: float) -> float:
    """Measure of {s : P1 interpolant of the normal jump <= tol} along the defect.

    With the jump piecewise linear between defect nodes this is the total length of the
    defect edges whose two end nodes are both closed (|jump| <= tol); the tips count as closed
    (their jump is zero by construction).
    """
    closed = np.asarray(jump) <= tol
    both = closed[:-1] & closed[1:]
    return float(np.sum(np.diff(np.asarray(s))[both]))


class Post:
    """Lazy post-processing of one solution: each attribute is computed on first access.

    ``Post(qp, sol)`` or ``Post(qp, x=..., multipliers=...)``; ``E``, ``nu``, ``plane``
    override the material stored in ``qp.params``.
    """

    def __init__(self, qp, sol=None, *, x=None, multipliers=None, E=None, nu=None, plane=None):
        if sol is not None:
            x = sol.x if x is None else x
            multipliers = sol.multipliers if multipliers is None else multipliers
        if x is None:
            raise InputError("post-processing needs a solution with displacements (x is None: the solve failed?)")
        _geometry(qp)
        self.qp = qp
        self.x = np.asarray(x, dtype=float)
        self.multipliers = None if multipliers is None else np.asarray(multipliers, dtype=float)
        self._material = (E, nu, plane)

    @cached_property
    def material(self) -> tuple[float, float, str]:
        """(E, nu, plane)."""
        return material(self.qp, *self._material)

    @property
    def nodes(self) -> np.ndarray:
        """Reference node coordinates (2, nnodes)."""
        return _geometry(self.qp).nodes

    @property
    def triangles(self) -> np.ndarray:
        """Triangles (3, ntri) as node ids."""
        return _geometry(self.qp).cells

    @cached_property
    def displacement(self) -> np.ndarray:
        """(nnodes, 2)."""
        return nodal_displacement(self.qp, self.x)

    @cached_property
    def strain(self) -> np.ndarray:
        """(ntri, 3): eps11, eps22, eps12."""
        return strains(self.qp, self.x)

    @cached_property
    def stress(self) -> dict[str, np.ndarray]:
        """Per triangle: s11, s22, s12, s33, von_mises."""
        return stresses(self.qp, self.x, *self.material)

    @property
    def von_mises(self) -> np.ndarray:
        """Von Mises stress per triangle."""
        return self.stress["von_mises"]

    @cached_property
    def defect(self) -> dict[str, np.ndarray]:
        """See :func:`defect_fields`."""
        return defect_fields(self.qp, self.x, self.multipliers)

    def deformed(self, scale: float = 1.0) -> np.ndarray:
        """X + scale u, (2, nnodes)."""
        return self.nodes + scale * self.displacement.T


# ----------------------------------------------------------------------------- transfer
def _grid_spacing(coord: np.ndarray) -> tuple[float, float]:
    c = np.unique(np.round(coord, 12))
    return float(c[0]), float(np.diff(c).min()) if c.size > 1 else 1.0


def locate(qp_coarse, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For points (2, k) strictly inside coarse triangles: the triangle index and barycentrics (k, 3).

    The coarse mesh must be a structured (tensor) triangulation such as the thin-defect scene's:
    its triangles are bucketed by the grid cell containing their centroid and each point is tested
    against the triangles of its cell. A point on the defect would be ambiguous (two coincident
    copies), so pass points that are strictly inside triangles (e.g. fine-triangle centroids).
    """
    g = _geometry(qp_coarse)
    P, T = g.nodes, g.cells
    x0, hx = _grid_spacing(P[0])
    y0, hy = _grid_spacing(P[1])
    ny = int(round((P[1].max() - y0) / hy)) + 2
    cen = P[:, T].mean(axis=1)
    key_t = np.floor((cen[0] - x0) / hx).astype(np.int64) * ny + np.floor((cen[1] - y0) / hy).astype(np.int64)
    order = np.argsort(key_t, kind="stable")
    keys = key_t[order]
    pts = np.asarray(points, dtype=float)
    kx = np.clip(np.floor((pts[0] - x0) / hx).astype(np.int64), 0, None)
    ky = np.clip(np.floor((pts[1] - y0) / hy).astype(np.int64), 0, None)
    key_p = kx * ny + ky
    lo = np.searchsorted(keys, key_p, "left")
    cnt = np.searchsorted(keys, key_p, "right") - lo
    found = np.full(pts.shape[1], -1, dtype=np.int64)
    bary = np.zeros((pts.shape[1], 3))
    for k in range(int(cnt.max(initial=0))):
        idx = np.flatnonzero((cnt > k) & (found < 0))
        if idx.size == 0:
            break
        cand = order[lo[idx] + k]
        b = barycentric(P[:, T[:, cand]], pts[:, idx])
        ok = b.min(axis=1) >= -1e-9
        found[idx[ok]] = cand[ok]
        bary[idx[ok]] = b[ok]
    if np.any(found < 0):
        raise InputError(f"{int(np.sum(found < 0))} points are not inside the coarse mesh "
                         f"(meshes must cover the same domain; the transfer needs tensor meshes)")
    return found, bary


def barycentric(tri_xy: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (k, 3) of points (2, k) in triangles given as (2, 3, k) vertices."""
    a, b, c = tri_xy[:, 0], tri_xy[:, 1], tri_xy[:, 2]
    v0, v1, v2 = b - a, c - a, pts - a
    det = v0[0] * v1[1] - v0[1] * v1[0]
    l1 = (v2[0] * v1[1] - v2[1] * v1[0]) / det
    l2 = (v0[0] * v2[1] - v0[1] * v2[0]) / det
    return np.stack([1 - l1 - l2, l1, l2], axis=1)


def prolongate(qp_coarse, x_coarse: np.ndarray, qp_fine) -> np.ndarray:
    """Interpolate a coarse P1 solution onto the nodes of a nested finer mesh, side by side.

    Each fine triangle is located by its centroid in the coarse triangle that contains it (so
    on the correct side of the defect); the coarse P1 field of that triangle is evaluated at the
    fine triangle's three vertices. A fine node on the defect thus gets the value of the coarse
    field on its own face (upper copies from above, lower copies from below). Returns the vector
    of the fine QP's free unknowns (clamped values are zero on both meshes).
    """
    uc = nodal_displacement(qp_coarse, x_coarse)
    gf = _geometry(qp_fine)
    Pf, Tf = gf.nodes, gf.cells
    tc, _ = locate(qp_coarse, Pf[:, Tf].mean(axis=1))
    gc = _geometry(qp_coarse)
    Tc, Pc = gc.cells, gc.nodes
    tri_xy = Pc[:, Tc[:, tc]]
    U = np.zeros((Pf.shape[1], 2))
    for i in range(3):
        b = barycentric(tri_xy, Pf[:, Tf[i]])  # (ntri_f, 3)
        val = np.einsum("tk,tkc->tc", b, uc[Tc[:, tc].T])
        U[Tf[i]] = val
    return free_vector(qp_fine, U)


def mass_norm2(qp, x: np.ndarray) -> float:
    """Squared L2 norm of the P1 displacement field, sum over triangles of A/12 (sum e_i^2 + (sum e_i)^2)."""
    g = _geometry(qp)
    T = g.cells
    _, area = shape_gradients(g.nodes, T)
    u = nodal_displacement(qp, x)[T]  # (3, ntri, 2)
    per = (u ** 2).sum(axis=0) + u.sum(axis=0) ** 2
    return float(np.sum(area[:, None] / 12.0 * per))
