"""The scene key ``element`` of a thin-defect scene: ``"P1"`` (default) or quadratic triangles.

* ``"P1"``: linear triangles, the QP of :mod:`dualfem.problems.thin_defect` unchanged bit for bit.
* ``"P2"``: quadratic triangles (scikit-fem's ``ElementVector(ElementTriP2())``) on the same cut mesh.
* ``"P2-quarter-point"``: P2 with the mid-edge node of every edge touching a crack tip moved to a quarter of
  the edge from the tip (isoparametric ``MeshTri2``): the displacement then holds the sqrt(r) term of a
  crack tip (Barsoum 1976; Henshell and Shaw 1975).

Nodes: the cut mesh's vertices (ids unchanged), then one node per mesh edge (edge k of
:func:`dualfem.problems._quadratic.edge_table`, node ``nv + k``; scikit-fem's facet order). Unknown
``node_dofs[c, i]`` is component c of node i, as in P1; scikit-fem's P2 vector DOF ``2 i + c`` is the same
(node, component) order. The crack interface: :mod:`dualfem.problems._quadratic` (vertex and mid-edge pairs,
their normals, the isoparametric row-sum weights); pairs are ordered defect by defect along the arc length.

Supports and loads as P1 does, on the P2 nodes: the legacy bottom clamp fixes every node on x2 = 0 (mid-edge
nodes included), ``[[boundary]]`` clamps / rollers the nodes of a side's edges, the rigid-body removal picks
P2 nodes; side tractions and ``remote_stress`` are integrated with the quadratic edge functions (5-point Gauss
per edge), ``body_force`` with scikit-fem on the (isoparametric) cells, a defect's ``face_pressure`` p as
``p w_j nu_j`` at each pair (the consistent P2 load of a constant pressure: w_j are the edge row sums). Friction
(Tresca, Coulomb) acts on every P2 pair as on P1's. ``refine = "adaptive"`` re-meshes as on P1, the estimator being
:mod:`dualfem.numerics.estimator_p2` and the size rule's order 2 (docs/elements.md).

The QP's ``geometry`` holds every P2 node (``nodes`` (2, nv + ne)), the linear triangles as ``cells`` (vertex
ids only) and ``element``: post-processing that assumes P1 (the P1 SIF methods) refuses such a QP; VTU files
rebuild the 6-node cells (:mod:`dualfem.numerics.p2`).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.errors import InputError

from .. import _boundary as bd
from .._interface import DoubledNodes, delta_free_part, local_unknowns
from .._quadratic import edge_index, edge_table, edge_weights, mid_edge_pairs, quadratic_interface
from .cut import Cut
from .mesh import rotate

ELEMENTS = ("P1", "P2", "P2-quarter-point")
#: Gauss points per boundary edge for the P2 tractions (exact for a quadratic function times quadratic data)
_EDGE_GAUSS = 5


def check_element(value) -> str:
    """The key ``element``: one of :data:`ELEMENTS` (InputError naming the choices)."""
    if not isinstance(value, str) or value not in ELEMENTS:
        raise InputError(f"element must be one of {', '.join(repr(e) for e in ELEMENTS)}, got {value!r}")
    return value


def size_of_mesh(problem) -> int:
    """2 x (vertices + edges) of the cut mesh (meshing it): the P2 unknowns before supports are removed (the adaptive
    loop's budget check, :meth:`dualfem.problems.adaptive.Adaptive.size_of_mesh`)."""
    c, _ = problem.cut()
    return 2 * (int(c.points.shape[1]) + int(edge_table(c.triangles)[0].shape[1]))


def crack_edges(c: Cut) -> np.ndarray:
    """The defects' edges (2, k) on the "-" face, defect by defect from the first point: (tip, lower...,
    tip) of each defect joined in order."""
    out = []
    for k in range(c.length.size):
        seq = np.concatenate([c.tips[2 * k:2 * k + 1], c.lower[c.defect_id == k], c.tips[2 * k + 1:2 * k + 2]])
        out.append(np.stack([seq[:-1], seq[1:]]))
    return np.hstack(out) if out else np.zeros((2, 0), np.int64)


def p2_points(c: Cut, edges: np.ndarray, quarter: bool) -> np.ndarray:
    """The P2 nodes (2, nv + ne), reference frame: vertices, then edge midpoints; with ``quarter`` the mid-edge
    node of each edge touching a tip at a quarter of the edge from the tip."""
    P = c.points
    mid = 0.5 * (P[:, edges[0]] + P[:, edges[1]])
    if quarter and c.tips.size:
        is_tip = np.zeros(P.shape[1], bool)
        is_tip[c.tips] = True
        for a, b in ((0, 1), (1, 0)):
            sel = is_tip[edges[a]] & ~is_tip[edges[b]]
            mid[:, sel] = 0.75 * P[:, edges[a][sel]] + 0.25 * P[:, edges[b][sel]]
    return np.hstack([P, mid])


def p2_interface(c: Cut, points: np.ndarray, edges: np.ndarray) -> tuple[DoubledNodes, np.ndarray, np.ndarray]:
    """(the P2 interface (reference frame), its tangents (2, m), its arc lengths (m,)), pairs sorted defect by
    defect along the arc length."""
    ce = crack_edges(c)
    mid = mid_edge_pairs(c, edges, ce)
    triples = np.stack([ce[0], edge_index(edges, ce[0], ce[1]) + c.points.shape[1], ce[1]])
    q = quadratic_interface(c, points, mid, edge_weights(points, triples, points.shape[1]))
    first = mid.edge[0]
    s_first = np.where(mid.vertex_pairs[0] >= 0, c.s[np.maximum(mid.vertex_pairs[0], 0)], 0.0)
    s = np.concatenate([c.s, s_first + np.linalg.norm(points[:, mid.lower] - points[:, first], axis=0)])
    nm = q.normals[:, c.lower.size:]
    tangents = np.hstack([c.tangents, np.stack([nm[1], -nm[0]])])
    order = np.lexsort((s, q.defect_id))
    q = DoubledNodes(points=points, lower=q.lower[order], upper=q.upper[order], defect_id=q.defect_id[order],
                     normals=q.normals[:, order], weights=q.weights[order])
    return q, tangents[:, order], s[order]


def basis(points: np.ndarray, triangles: np.ndarray, quarter: bool, intorder: int | None = None):
    """scikit-fem's P2 vector basis on the nodes ``points`` (2, nv + ne) (isoparametric when ``quarter``); its
    quadrature of degree ``intorder`` (None: scikit-fem's default, 4)."""
    from skfem import Basis, ElementTriP2, ElementVector, MeshTri, MeshTri2

    nv = int(triangles.max()) + 1
    pts = np.ascontiguousarray(points if quarter else points[:, :nv])
    mesh = MeshTri2(pts, np.ascontiguousarray(triangles)) if quarter else MeshTri(pts, np.ascontiguousarray(triangles))
    return Basis(mesh, ElementVector(ElementTriP2()), intorder=intorder)


def stiffness(points: np.ndarray, triangles: np.ndarray, edges: np.ndarray, quarter: bool, lam: float, mu: float,
              node_dofs: np.ndarray) -> sp.csc_matrix:
    """P2 plane elasticity stiffness on the free unknowns ``node_dofs`` (2, n_nodes; -1 fixed), canonical CSC.
    scikit-fem's default quadrature (degree 4: exact on straight P2 triangles). RuntimeError unless scikit-fem's
    facets are ``edges`` (node nv + k = edge k) and its DOFs the nodes' components."""
    from skfem import asm
    from skfem.models.elasticity import linear_elasticity

    b = basis(points, triangles, quarter)
    if b.N != node_dofs.size or not np.array_equal(b.mesh.facets, edges):
        raise RuntimeError(f"the P2 basis ({b.N} DOFs) does not number the nodes' {node_dofs.size} components as "
                           f"problems/_quadratic.edge_table does")
    free = node_dofs.T.ravel()
    keep = np.flatnonzero(free >= 0)          # basis DOF 2 i + c in (node, component) order: unknowns ascending
    K = asm(linear_elasticity(lam, mu), b).tocsr()[keep][:, keep].tocsc()
    K.sort_indices()
    K.sum_duplicates()
    return K


def delta_free(problem, lam: float, mu: float, R: np.ndarray) -> dict:
    """The delta-free assembly of a P2 thin-defect scene (the dict of ``ThinDefect._delta_free``; its ``cut``
    is the P2 interface, so the interface term and B come from the same code as P1's)."""
    p = problem.params
    quarter = p["element"] == "P2-quarter-point"
    c, pts1 = problem.cut()
    edges, _ = edge_table(c.triangles)
    P_ref = p2_points(c, edges, quarter)
    P = rotate(P_ref, float(p["rotate_deg"]), np.array([p["width"], p["height"]]) / 2)
    sides = p2_sides(problem, edges)
    if problem._loads is None:
        tol = 1e-9 * max(p["width"], p["height"])
        from .assemble import free_dofs

        node_dofs = free_dofs(np.flatnonzero(np.abs(P_ref[1]) <= tol), P.shape[1])
    else:
        node_dofs = bd.dof_numbering(bd.fixed_mask(problem._loads, P, sides))
    n = int(node_dofs.max()) + 1
    K_el = stiffness(P, c.triangles, edges, quarter, lam, mu, node_dofs)
    q, tangents, s = p2_interface(c, P_ref, edges)
    part = delta_free_part(node_dofs, q, (R @ q.normals).T, tangents=(R @ tangents).T[:, None, :], front=c.tips, s=s)
    maps = {"nodes": P, "triangles": c.triangles, "node_dofs": node_dofs}
    return {"cut": q, "n": n, "K_el": K_el, "local": local_unknowns(node_dofs, q.lower, q.upper), "maps": maps,
            "interface": part, "p2": {"edges": edges, "points_ref": P_ref, "sides": sides, "quarter": quarter}}


def p2_sides(problem, edges: np.ndarray) -> dict[str, np.ndarray]:
    """Boundary edges per side as P2 node triples (3, k) = (first vertex, last vertex, mid-edge node)."""
    nv = problem.cut()[0].points.shape[1]
    out = {}
    for side, e in problem._box_sides().items():
        out[side] = np.vstack([e, edge_index(edges, e[0], e[1]) + nv])
    return out


# ------------------------------------------------------------------------------------------------ loads
def _edge_forces(F: np.ndarray, P: np.ndarray, triples: np.ndarray, fn, scale: float, what: str) -> None:
    """Add ``scale * int_edge t N_i ds`` to ``F`` (2, n) for the straight edges ``triples`` (3, k) = (a, b, mid)
    of the P2 nodes ``P`` (reference frame); ``fn(X)`` (X (2, k, q)) gives the traction (2, k, q)."""
    if triples.shape[1] == 0:
        return
    g, wg = np.polynomial.legendre.leggauss(_EDGE_GAUSS)
    xi, wg = 0.5 * (g + 1), 0.5 * wg
    N = np.stack([2 * (xi - 0.5) * (xi - 1), 2 * xi * (xi - 0.5), 4 * xi * (1 - xi)])     # a, b, mid
    a, b = P[:, triples[0]], P[:, triples[1]]
    X = a[:, :, None] + (b - a)[:, :, None] * xi
    L = np.linalg.norm(b - a, axis=0)
    vals = np.broadcast_to(bd.evaluate(fn, X, what), X.shape)
    contrib = scale * np.einsum("ckq,q,iq,k->cik", vals, wg, N, L)
    for c in range(2):
        F[c] += np.bincount(triples.ravel(), weights=contrib[c].ravel(), minlength=F.shape[1])


def _body_forces(F: np.ndarray, a: dict, triangles: np.ndarray, field, scale: float) -> None:
    """Add the consistent P2 nodal forces of the body force ``field`` (reference frame) to ``F`` (2, n): degree-6
    quadrature, exact for quadratic data times P2 functions on straight cells (and for the resultant of quadratic
    data on a quarter-point cell, whose Jacobian is quadratic)."""
    from skfem import LinearForm, asm

    info = a["p2"]
    b = basis(info["points_ref"], triangles, info["quarter"], intorder=6)    # exact for data of degree 2

    @LinearForm
    def form(v, w):
        val = field(w.x) if callable(field) else np.asarray(field, float)[:, None, None] * np.ones_like(w.x)
        return val[0] * v[0] + val[1] * v[1]

    with np.errstate(all="ignore"):
        try:
            f = asm(form, b)
        except InputError:
            raise
        except Exception as exc:                               # noqa: BLE001 - an expression that breaks
            raise InputError(f"body_force cannot be evaluated in the body: {type(exc).__name__}: {exc}") from None
    if not np.all(np.isfinite(f)):
        raise InputError("body_force gives NaN or infinite values in the body; it must be finite there")
    F += scale * f.reshape(-1, 2).T


def nodal_load(problem, a: dict) -> np.ndarray:
    """Nodal forces (2, n_nodes) of every load on the P2 nodes, times ``load_scale``, in the rotated frame: the
    legacy top traction ``load``, or the ``[[boundary]]`` tractions, ``remote_stress`` and ``body_force``."""
    from .mesh import rotation

    p = problem.params
    info, scale = a["p2"], float(p["load_scale"])
    P_ref, sides = info["points_ref"], info["sides"]
    F = np.zeros((2, P_ref.shape[1]))
    spec = problem._loads
    with np.errstate(all="ignore"):
        if spec is None:
            g = problem._traction

            def top(X):
                val = g(X[0], X[1])
                return np.stack(np.broadcast_arrays(*val, X[0])[:2]) if isinstance(val, tuple) else \
                    np.stack([np.zeros(X.shape[1:]), np.broadcast_to(val, X.shape[1:])])

            _edge_forces(F, P_ref, sides["top"], top, scale, "on the top side")
        else:
            stress = spec.stress
            for side in ("left", "right", "bottom", "top"):
                s = spec.side(side)
                if s.traction is not None:
                    _edge_forces(F, P_ref, sides[side], s.traction, scale, f"on the {side} side")
                if stress is not None and s.support == "free":
                    t = stress @ bd.outward_normal(side, 2)
                    _edge_forces(F, P_ref, sides[side], lambda X, t=t: t[:, None, None] * np.ones(X.shape[1:]), scale,
                                 f"on the {side} side")
            if spec.body_force is not None:
                _body_forces(F, a, a["maps"]["triangles"], spec.body_force, scale)
    R = rotation(float(p["rotate_deg"]))
    if p["rotate_deg"] != 0:
        F = R @ F
    if any(d.get("face_pressure") is not None for d in problem._defects):    # p w_j nu_j: exact for constant p
        q = a["cut"]
        F = F + bd.face_pressure_forces(q.upper, q.lower, R @ q.normals, q.weights, scale * problem._pressures(q),
                                        F.shape[1])
    if spec is not None:
        bd.check_balance(spec, a["maps"]["nodes"], sides, F)
    return F
