"""The ``element = "P2"`` discretization of :mod:`dualfem.problems.three_d`: quadratic tetrahedra on the cut mesh.

* Mesh and pairs: :mod:`dualfem.problems._quadratic3d` (mid-edge nodes, the defect pairs at vertices and
  mid-edge nodes, positive nodal weights: P1 lumping on the 4 sub-triangles of each P2 face).
* Stiffness: the P2 elasticity matrix, vectorised like the P1 one (:func:`stiffness`; straight tetrahedra: the
  P2 strains are linear, their products quadratic, a 4-point degree-2 rule is exact); equal to scikit-fem's
  ``asm(linear_elasticity(lam, mu), Basis(mesh, ElementVector(ElementTetP2())))`` (:func:`skfem_stiffness`,
  the test's reference), which took 7.4 s where this takes well under one on a 34 k-unknown penny.
* Supports: a side's mid-edge nodes are on the side (both ends are), so the supports of
  :mod:`dualfem.problems._boundary` act on the P2 nodes of each side's triangles; the legacy bottom clamp fixes
  every P2 node at z = 0; the rigid-body completion picks among all P2 nodes.
* Loads: consistent P2 nodal forces (the six P2 shape functions of each side triangle, the ten of each
  tetrahedron for a body force) with the Gauss rules of :func:`dualfem.problems._boundary.simplex_rule`
  (exact for constants and for linear data); a defect's ``face_pressure`` as consistent P2 forces too
  (:func:`face_pressure_weights`: the lumped weights of the delta term would give a uniform pressure's corners
  A/12 and mid-edge nodes A/4 per face instead of 0 and A/3, and measured a 4.2 % opening error on a penny where
  tension gives 3.5 %).
"""
from __future__ import annotations

import numpy as np

from dualfem.errors import InputError
from dualfem.numerics.p1 import tet_gradients

from .. import _boundary as bd
from .._quadratic3d import TET_EDGES, QuadraticTets, interface_pairs, quadratic_tets, shape_values
from .assemble import _restrict, _symmetric, node_pattern
from .cut import Cut3

#: the values of the scene key ``element`` in 3D
ELEMENTS = ("P1", "P2")
#: about how many P2 nodes per tetrahedron of a gmsh mesh (vertices + edges; measured on penny meshes of 8-18 k
#: tetrahedra: 1.41-1.45)
P2_NODES_PER_TET = 1.5


def check_element(value) -> str:
    """The ``element`` key: "P1" or "P2" (InputError otherwise; the 2D-only quarter-point element refused)."""
    if isinstance(value, str) and value.strip() == "P2-quarter-point":
        raise InputError("element = 'P2-quarter-point' is 2D only (quarter-point triangles at crack tips); "
                         "in 3D use element = 'P1' or 'P2'")
    if not isinstance(value, str) or value.strip() not in ELEMENTS:
        raise InputError(f"element must be one of {', '.join(repr(e) for e in ELEMENTS)} in 3D, got {value!r}")
    return value.strip()


def mesh(c: Cut3) -> tuple[QuadraticTets, object]:
    """(the P2 mesh of the cut in the reference frame, the defect pairs of :func:`interface_pairs`)."""
    q = quadratic_tets(c.points, c.tets)
    return q, interface_pairs(q, c, c.faces)


#: the 4-point degree-2 rule on a tetrahedron (barycentric points, weights summing to 1): exact for the products
#: of P2 strains on straight tetrahedra
_QA, _QB = 0.5854101966249685, 0.1381966011250105
_QUAD = np.full((4, 4), _QB) + np.eye(4) * (_QA - _QB)


def gradients(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Gradients (4, 10, 3, nt) of the ten P2 shape functions (order of :data:`TET_EDGES` after the corners) at
    the points of :data:`_QUAD`, times sqrt(weight x volume); ``cells`` (10, nt) positively oriented."""
    g, vol = tet_gradients(points, cells[:4])                          # (4, 3, nt), (nt,)
    if np.any(vol <= 0):
        raise InputError("a tetrahedron of the mesh is degenerate or inverted (internal error of the mesh)")
    G = np.empty((4, 10, 3, cells.shape[1]))
    for q, lam in enumerate(_QUAD):
        G[q, :4] = (4 * lam - 1)[:, None, None] * g
        for e, (i, j) in enumerate(TET_EDGES):
            G[q, 4 + e] = 4 * (lam[i] * g[j] + lam[j] * g[i])
    return G * np.sqrt(vol / 4)[None, None, None, :]


_PAIRS10 = np.triu_indices(10, 1)


def stiffness(points: np.ndarray, cells: np.ndarray, lam: float, mu: float, node_dofs: np.ndarray, n: int):
    """The P2 elasticity stiffness (n x n, canonical CSC) on the unknowns ``node_dofs`` (3, nn): ``points``
    (3, nn) all P2 nodes as solved, ``cells`` (10, nt). As the P1 assembly (:func:`.assemble.stiffness`): each
    cell's nodes sorted, the 45 off-diagonal 3 x 3 blocks summed onto the distinct node pairs and the 10
    diagonal ones onto the nodes, block (a, b) = sum_q lam g_a g_b' + mu g_b g_a' + mu (g_a . g_b) I; the
    matrix equals scikit-fem's ``asm(linear_elasticity(lam, mu), ...)`` on ElementTetP2 (tested) in a
    fraction of its time."""
    nn = points.shape[1]
    G = gradients(points, cells)
    o = np.argsort(cells, axis=0)
    ts = np.take_along_axis(cells, o, 0).astype(np.int64)
    G = np.take_along_axis(G, o[None, :, None, :], 1)
    ia, ib = _PAIRS10
    rows, cols, pos = node_pattern(ts[ia], ts[ib], nn)
    node = ts.ravel()
    M = {}
    Md = {}
    for r in range(3):
        for c in range(3):
            M[r, c] = np.einsum("qpt,qpt->pt", G[:, ia, r], G[:, ib, c])
            Md[r, c] = np.einsum("qpt,qpt->pt", G[:, :, r], G[:, :, c])
    tr, trd = M[0, 0] + M[1, 1] + M[2, 2], Md[0, 0] + Md[1, 1] + Md[2, 2]
    V, Vd = np.empty((rows.size, 3, 3)), np.empty((nn, 3, 3))
    for r in range(3):
        for c in range(3):
            w = lam * M[r, c] + mu * M[c, r] + (mu * tr if r == c else 0.0)
            wd = lam * Md[r, c] + mu * Md[c, r] + (mu * trd if r == c else 0.0)
            V[:, r, c] = np.bincount(pos, weights=w.ravel(), minlength=rows.size)
            Vd[:, r, c] = np.bincount(node, weights=wd.ravel(), minlength=nn)
    del M, Md, G, pos
    return _restrict(_symmetric(rows, cols, V, Vd, nn), np.asarray(node_dofs, dtype=np.int64), n)


def skfem_stiffness(points: np.ndarray, tets: np.ndarray, lam: float, mu: float):
    """scikit-fem's P2 elasticity stiffness (3 nn x 3 nn, unknown 3 i + c, all unknowns) of the P1 mesh
    ``points`` (3, nv), ``tets`` (4, nt): the reference of :func:`stiffness` (the nodes of
    :func:`dualfem.problems._quadratic3d.quadratic_tets`)."""
    from skfem import Basis, ElementTetP2, ElementVector, MeshTet, asm
    from skfem.models.elasticity import linear_elasticity

    basis = Basis(MeshTet(np.ascontiguousarray(points, dtype=float), np.ascontiguousarray(tets)),
                  ElementVector(ElementTetP2()), intorder=2)
    return asm(linear_elasticity(lam, mu), basis).tocsc()


def sides(q: QuadraticTets, sides1: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Each side's triangles (6, k) with their mid-edge nodes (for the support masks: the nodes on the side)."""
    return {k: np.vstack([f, q.simplex_midnodes(f)]) for k, f in sides1.items()}


def integrate(out: np.ndarray, q: QuadraticTets, simplices: np.ndarray, f, scale: float, what: str) -> None:
    """Add the consistent P2 nodal forces of ``f`` (a Field, or a constant vector (3,)) over the triangles (3, k) or
    tetrahedra (4, k) ``simplices`` (vertex ids) into ``out`` (3, nv + ne)."""
    if simplices.shape[1] == 0:
        return
    kv = simplices.shape[0]
    lam, w = bd.simplex_rule(kv - 1)
    N = shape_values(lam)                                                   # (nq, nloc)
    ids = np.vstack([simplices, q.simplex_midnodes(simplices)])             # (nloc, k)
    V = q.points[:, simplices]                                              # (3, kv, k)
    meas = bd._measure(V)
    X = np.einsum("dkf,qk->dfq", V, lam)                                    # (3, k, nq)
    if isinstance(f, np.ndarray):
        vals = np.broadcast_to(f[:, None, None], X.shape)
    else:
        vals = bd.evaluate(f, X, what)
    contrib = scale * np.einsum("cfq,q,qa->caf", vals, w, N) * meas[None, None, :]
    for c in range(out.shape[0]):
        out[c] += np.bincount(ids.ravel(), weights=contrib[c].ravel(), minlength=out.shape[1])


def nodal_forces(spec, q: QuadraticTets, sides1: dict[str, np.ndarray], scale: float = 1.0) -> np.ndarray:
    """P2 :func:`dualfem.problems._boundary.nodal_forces`: (3, nv + ne), reference frame, times ``scale``."""
    F = np.zeros(q.points.shape)
    with np.errstate(all="ignore"):
        for side in bd.SIDES[3]:
            s = spec.side(side)
            if s.traction is not None:
                integrate(F, q, sides1[side], s.traction, scale, f"on the {side} side")
            if spec.stress is not None and s.support == "free":
                integrate(F, q, sides1[side], spec.stress @ bd.outward_normal(side, 3), scale, f"on the {side} side")
        if spec.body_force is not None:
            integrate(F, q, q.tets, spec.body_force, scale, "in the body")
    return F


def face_pressure_weights(q: QuadraticTets, pairs, faces: np.ndarray, fields: list) -> np.ndarray:
    """Per defect pair j: int over the defect of N_j p (the consistent P2 force of the pressure p of its defect,
    a Field of the reference frame, None: 0), from the "-" triangles ``faces`` (3, nf) and their mid-edge nodes;
    nodes that are no pair (the front) take none. With these as weights and pressure 1,
    :func:`dualfem.problems._boundary.face_pressure_forces` gives the consistent forces."""
    f = np.asarray(faces, dtype=np.int64)
    nn = q.points.shape[1]
    row_of = np.full(nn, -1, np.int64)
    row_of[pairs.lower] = np.arange(pairs.lower.size)
    ids = np.vstack([f, q.simplex_midnodes(f)])                           # (6, nf) "-" nodes
    rows = np.where(ids >= 0, row_of[ids], -1)
    owner = rows[:3].max(axis=0)                                          # a doubled corner: the face's defect
    defect = np.where(owner >= 0, np.asarray(pairs.defect_id)[np.maximum(owner, 0)], -1)
    lam, w = bd.simplex_rule(2)
    N = shape_values(lam)                                                 # (nq, 6)
    V = q.points[:, f]                                                    # (3, 3, nf)
    X = np.einsum("dkf,qk->dfq", V, lam)
    area = bd._measure(V)
    out = np.zeros(pairs.lower.size)
    for k, field in enumerate(fields):
        sel = np.flatnonzero(defect == k)
        if field is None or sel.size == 0:
            continue
        with np.errstate(all="ignore"):
            p = np.asarray(field(X[:, sel]), dtype=float)[0]             # (ns, nq)
        c = np.einsum("fq,q,qa->af", p, w, N) * area[sel]                 # (6, ns)
        r = rows[:, sel]
        ok = r >= 0
        out += np.bincount(r[ok], weights=c[ok], minlength=out.size)
    return out


class _Traction:
    """The legacy top traction g(x, y) -> (t_x, t_y, t_z) as a field of X (3, ...)."""

    key = "load"
    constant = False

    def __init__(self, g) -> None:
        self.g = g

    def __call__(self, X: np.ndarray) -> np.ndarray:
        return np.array([np.broadcast_to(np.asarray(v, dtype=float), X[0].shape) for v in self.g(X[0], X[1])])


def top_forces(q: QuadraticTets, top: np.ndarray, g, scale: float) -> np.ndarray:
    """P2 nodal forces (3, nv + ne) of the legacy top traction ``scale * g(x, y)`` on the triangles ``top``."""
    F = np.zeros(q.points.shape)
    with np.errstate(all="ignore"):
        integrate(F, q, top, _Traction(g), scale, "on the top face")
    return F
