"""Supports and loads of a box-shaped body in 2D or 3D: the scene keys ``[[boundary]]``, ``body_force``,
``remote_stress`` (and the per-defect ``face_pressure`` forces), dimension-generic.

The body is the box (0, width) x (0, height) in 2D, (0, width) x (0, depth) x (0, height) in 3D, in its
reference (unrotated) frame; every key below is read in that frame (a problem that rotates the body
rotates the resulting forces with it). Sides: ``left``/``right`` x = 0 / width, ``bottom``/``top`` the
last coordinate = 0 / its length (y in 2D, z in 3D), and in 3D ``front``/``back`` y = 0 / depth.
Units: forces per unit area of the body's surface (stress, e.g. MPa) for tractions and stresses, force
per unit volume for the body force; the nodal forces are in force units (per unit thickness in 2D).

* ``[[boundary]]`` tables ``{side, support, traction}``: ``support`` = ``"clamp"`` (every component
  fixed), ``"roller"`` (the normal component fixed), ``"free"`` (default); ``traction`` = a vector of
  ``dim`` numbers or expression strings in x, y (, z) (:mod:`dualfem.core.expressions`): the force per
  area applied to the body's outer surface on that side (so a pull on the top side is +y in 2D).
  A side not listed is free and carries no traction (but see ``remote_stress``).
* ``body_force``: a vector of numbers or expressions, force per unit volume (gravity: [0, -rho g]).
* ``remote_stress``: a symmetric dim x dim tensor of numbers [[sxx, sxy], [sxy, syy]]: the traction
  sigma.n (n the outward unit normal) on every side without a support (``free`` or not listed). It
  may not be combined with a ``traction`` on the same side.

Supports: when the supports leave rigid-body motions free (no support at all, or e.g. only a roller),
exactly those motions are removed by fixing single components at well-separated extreme nodes
(:func:`fixed_mask`: 3 components in 2D, 6 in 3D without any support, the 3-2-1 rule), chosen so that
the rigid-mode matrix restricted to them is well conditioned; the loads must then be in equilibrium
(:func:`check_balance`), and the reactions at these components are zero: an uncracked body under
``remote_stress`` alone carries exactly the remote stress.

API: :func:`parse_loads` (the keys -> a frozen :class:`LoadSpec`, or None when none is given),
:func:`box_sides` (boundary facets per side), :func:`fixed_mask`, :func:`nodal_forces`,
:func:`check_balance`, :func:`dof_numbering` (the mask as ``node_dofs``), :func:`face_pressure_forces`,
:func:`parse_scalar` (a per-defect ``face_pressure``); for bodies of any shape (``problems/file_body``):
:func:`complete_supports`, :func:`free_modes_of`, :func:`check_balance_of`, :func:`integrate`.
"""
from __future__ import annotations

import math
from itertools import combinations

import numpy as np
import scipy.linalg

from dualfem.errors import InputError

from ._load_spec import (  # noqa: F401  (the API of this module: parsing and the sides)
    KEYS,
    SIDES,
    SUPPORTS,
    TABLE_KEYS,
    VARIABLES,
    Field,
    LoadSpec,
    Side,
    box_lengths,
    outward_normal,
    parse_field,
    parse_loads,
    parse_scalar,
    side_axis,
)

#: relative tolerance of a node lying on a side (of the largest box length)
SIDE_RTOL = 1e-9
#: the rigid-body completion must be at least this well conditioned (smallest / largest singular value)
MIN_CONDITION = 1e-3
#: net force / moment of loads on a body whose supports leave rigid motions free, relative to the loads
BALANCE_RTOL = 1e-8
#: cells per chunk when a body-force expression is integrated
_CHUNK = 20_000


# --------------------------------------------------------------------------- mesh sides
def _faces(cells: np.ndarray) -> np.ndarray:
    """All faces (nv - 1, nv * nc) of simplex cells (nv, nc): face i leaves out vertex i."""
    nv = cells.shape[0]
    return np.hstack([cells[[j for j in range(nv) if j != i]] for i in range(nv)])


def box_sides(nodes: np.ndarray, cells: np.ndarray, box: tuple[float, ...]) -> dict[str, np.ndarray]:
    """Boundary facets on each side of the box: {side: (dim, nf) node ids} (edges in 2D, triangles in 3D).

    ``nodes`` (dim, n) in the reference frame, ``cells`` (dim + 1, nc) simplices. A facet is on a side when
    all its nodes lie on the side's plane (within :data:`SIDE_RTOL` of the largest length) and it is a
    face of one cell only.
    """
    dim = nodes.shape[0]
    tol = SIDE_RTOL * max(box)
    cells = np.asarray(cells)
    out = {}
    for side in SIDES[dim]:
        axis, far = side_axis(side, dim)
        on = np.abs(nodes[axis] - (box[axis] if far else 0.0)) <= tol
        near = cells[:, on[cells].sum(axis=0) >= dim]          # cells with a whole face on the plane
        f = _faces(near)
        f = f[:, on[f].all(axis=0)]
        key = np.sort(f, axis=0)
        _, first, count = np.unique(key, axis=1, return_index=True, return_counts=True)
        out[side] = np.ascontiguousarray(f[:, np.sort(first[count == 1])])
    return out


# --------------------------------------------------------------------------- supports
def _modes(X: np.ndarray, comp: np.ndarray, centre: np.ndarray, length: float) -> np.ndarray:
    """Rows (k, nm) of the rigid-body modes at component comp[i] of points X[:, i]: translations, then the
    rotations (about the centre, divided by ``length``) in 2D (about z) or 3D (about x, y, z)."""
    dim, k = X.shape
    r = (X - centre[:, None]) / length
    rows = np.zeros((k, 3 if dim == 2 else 6))
    rows[np.arange(k), comp] = 1.0
    if dim == 2:
        rows[:, 2] = np.where(comp == 0, -r[1], r[0])
    else:                               # rotation about axis a: e_a x r
        for a in range(3):
            rot = np.cross(np.eye(3)[a], r.T).T            # (3, k)
            rows[:, 3 + a] = rot[comp, np.arange(k)]
    return rows


def _support_mask(spec: LoadSpec, n: int, sides: dict[str, np.ndarray]) -> np.ndarray:
    mask = np.zeros((spec.dim, n), dtype=bool)
    for s in spec.sides:
        ids = np.unique(sides[s.side])
        if s.support == "clamp":
            mask[:, ids] = True
        elif s.support == "roller":
            mask[side_axis(s.side, spec.dim)[0], ids] = True
    return mask


def _frame(nodes: np.ndarray) -> tuple[np.ndarray, float]:
    lo, hi = nodes.min(axis=1), nodes.max(axis=1)
    return 0.5 * (lo + hi), max(0.5 * float(np.linalg.norm(hi - lo)), 1e-300)


def free_modes(spec: LoadSpec, nodes: np.ndarray, sides: dict[str, np.ndarray]) -> np.ndarray:
    """The rigid-body motions the supports leave free: an orthonormal basis (nm, k) of mode coefficients
    (see :func:`_modes`; k = 0 when the supports hold the body)."""
    return free_modes_of(_support_mask(spec, nodes.shape[1], sides), nodes)


def free_modes_of(mask: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """:func:`free_modes` for a mask (dim, n) of fixed components (any body, not only a box)."""
    nm = 3 if mask.shape[0] == 2 else 6
    comp, idx = np.nonzero(mask)
    if idx.size == 0:
        return np.eye(nm)
    centre, length = _frame(nodes)
    R = _modes(nodes[:, idx], comp, centre, length)
    w, V = np.linalg.eigh(R.T @ R)
    return V[:, w <= 1e-10 * w.max()]


def _candidates(nodes: np.ndarray, exclude: np.ndarray | None = None) -> np.ndarray:
    """Extreme nodes: the maximisers of s . x for s in {-1, 0, 1}^dim \\ {0} (vertices of the hull), distinct."""
    dim = nodes.shape[0]
    dirs = [np.array(s, float) for s in np.ndindex(*(3,) * dim)]
    dirs = [d - 1 for d in dirs if np.any(d != 1)]
    dirs.sort(key=lambda d: (-int(np.count_nonzero(d)), tuple(d)))     # corners first
    if exclude is None:
        ids = [int(np.argmax(d @ nodes)) for d in dirs]
    else:
        ids = [int(np.argmax(np.where(exclude, -np.inf, d @ nodes))) for d in dirs]
    return np.array(list(dict.fromkeys(ids)), dtype=np.int64)


def fixed_mask(spec: LoadSpec, nodes: np.ndarray, sides: dict[str, np.ndarray]) -> np.ndarray:
    """Fixed components (dim, n) bool: clamp fixes every component of a side's nodes, roller the normal one;
    the rigid-body motions the supports leave free are then removed by fixing as many single components
    at extreme nodes (3 in 2D, 6 in 3D when there is no support), chosen by a column-pivoted QR of the
    free modes at the candidates and checked: the smallest singular value of the modes restricted to the
    chosen components is >= :data:`MIN_CONDITION` x the largest.

    ``nodes`` (dim, n): the coordinates of the body as it is solved (rotated, when the problem rotates it),
    ``sides`` from :func:`box_sides` (reference frame: the side of a node does not change by rotation).
    """
    return complete_supports(_support_mask(spec, nodes.shape[1], sides), nodes)


def complete_supports(mask: np.ndarray, nodes: np.ndarray, exclude: np.ndarray | None = None) -> np.ndarray:
    """The fixed components ``mask`` (dim, n) plus single components at extreme nodes that remove the rigid-body
    motions ``mask`` leaves free (see :func:`fixed_mask`; any body, not only a box); nodes where ``exclude``
    (n,) is True are never chosen (e.g. the doubled nodes of a defect)."""
    mask = mask.copy()
    N = free_modes_of(mask, nodes)
    k = N.shape[1]
    if k == 0:
        return mask
    dim = mask.shape[0]
    cand = _candidates(nodes, exclude)
    ci, cc = np.repeat(cand, dim), np.tile(np.arange(dim), cand.size)
    keep = ~mask[cc, ci]
    ci, cc = ci[keep], cc[keep]
    centre, length = _frame(nodes)
    M = _modes(nodes[:, ci], cc, centre, length) @ N             # (ncand, k)
    if M.shape[0] < k:
        raise InputError("the supports leave rigid-body motions free and no components are left to remove "
                         "them; add a support ([[boundary]] support = clamp or roller)")
    _, _, piv = scipy.linalg.qr(M.T, pivoting=True)
    sel = piv[:k]
    best = _condition(M[sel])
    if best < MIN_CONDITION:          # pivoting is greedy: try every choice of k candidates (few)
        for combo in combinations(range(M.shape[0]), k):
            c = _condition(M[list(combo)])
            if c > best:
                best, sel = c, np.array(combo)
    if best < MIN_CONDITION:
        raise InputError(f"the supports leave rigid-body motions free and they cannot be removed at well-separated "
                         f"nodes (condition {best:.1e}); add a support ([[boundary]] support = clamp or roller)")
    mask[cc[sel], ci[sel]] = True
    return mask


def _condition(A: np.ndarray) -> float:
    s = np.linalg.svd(A, compute_uv=False)
    return float(s[-1] / s[0]) if s[0] > 0 else 0.0


def check_balance(spec: LoadSpec, nodes: np.ndarray, sides: dict[str, np.ndarray], forces: np.ndarray) -> None:
    """InputError when the supports leave rigid-body motions free and the nodal ``forces`` (dim, n) (in the
    frame of ``nodes``) have a net force or moment along them beyond :data:`BALANCE_RTOL` of their size."""
    check_balance_of(free_modes(spec, nodes, sides), nodes, forces)


def check_balance_of(N: np.ndarray, nodes: np.ndarray, forces: np.ndarray) -> None:
    """:func:`check_balance` for the free rigid-body modes ``N`` of :func:`free_modes_of` (any body)."""
    if N.shape[1] == 0:
        return
    dim, n = forces.shape
    centre, length = _frame(nodes)
    net = np.zeros(N.shape[0])
    size = np.zeros(N.shape[0])
    for c in range(dim):
        rows = _modes(nodes, np.full(n, c), centre, length)   # (n, nm)
        net += forces[c] @ rows
        size += np.abs(forces[c]) @ np.abs(rows)
    proj, scale = N.T @ net, float(size.max())
    if np.abs(proj).max() > BALANCE_RTOL * max(scale, 1e-300):
        raise InputError(f"the loads are not in equilibrium (net force/moment {np.abs(proj).max():.3g} against "
                         f"loads of size {scale:.3g}) and the supports leave rigid-body motions free; add a "
                         f"support ([[boundary]] support = clamp or roller) or balance the loads")


# --------------------------------------------------------------------------- loads
def simplex_rule(k: int, n: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric points (q, k + 1) and weights (q,) summing to 1 on a k-simplex (k = 1, 2, 3): Gauss-
    Legendre with n points per direction (default 4 on edges and triangles, 3 on tetrahedra), collapsed
    (Duffy) on triangles and tetrahedra; exact for polynomials of degree 2 n - k at least (7 on edges,
    6 on triangles, 3 on tetrahedra: a P1 function times quadratic data)."""
    n = n or (3 if k == 3 else 4)
    g, wg = np.polynomial.legendre.leggauss(n)
    g, wg = 0.5 * (g + 1), 0.5 * wg
    if k == 1:
        return np.stack([1 - g, g], axis=1), wg
    if k == 2:
        u, v = np.meshgrid(g, g, indexing="ij")
        w = np.outer(wg, wg) * (1 - u)
        x, y = u, v * (1 - u)
        lam = np.stack([1 - x - y, x, y], axis=-1).reshape(-1, 3)
    else:
        u, v, t = np.meshgrid(g, g, g, indexing="ij")
        w = wg[:, None, None] * wg[None, :, None] * wg[None, None, :] * (1 - u) ** 2 * (1 - v)
        x, y, z = u, v * (1 - u), t * (1 - u) * (1 - v)
        lam = np.stack([1 - x - y - z, x, y, z], axis=-1).reshape(-1, 4)
    w = w.ravel()
    return lam, w / w.sum()


def _measure(V: np.ndarray) -> np.ndarray:
    """Measure (nf,) of simplices with vertex coordinates V (dim, k + 1, nf): length, area or volume."""
    E = V[:, 1:] - V[:, :1]                                  # (dim, k, nf)
    k = E.shape[1]
    G = np.einsum("dif,djf->fij", E, E)
    return np.sqrt(np.maximum(np.linalg.det(G), 0.0)) / math.factorial(k)



def evaluate(f, X: np.ndarray, what: str) -> np.ndarray:
    """``f(X)`` for a load expression ``f`` (its ``key`` names it; ``X`` (dim, ...) points), finite: any error
    of the expression, or a NaN or infinite value, is one InputError naming the key and ``what`` (where)."""
    key = getattr(f, "key", "load")
    try:
        vals = f(X)
    except InputError:
        raise
    except Exception as exc:                           # noqa: BLE001 - an expression that breaks
        raise InputError(f"{key} cannot be evaluated {what}: {type(exc).__name__}: {exc}") from None
    if not np.all(np.isfinite(vals)):
        raise InputError(f"{key} gives NaN or infinite values {what}; it must be finite there")
    return vals

def integrate(out: np.ndarray, nodes: np.ndarray, simplices: np.ndarray, f: Field | np.ndarray, scale: float,
               what: str) -> None:
    """Add the consistent P1 nodal forces of the field f (a Field, or a constant vector) over the simplices
    (k + 1, ns) into ``out`` (dim, n)."""
    if simplices.shape[1] == 0:
        return
    dim, n = out.shape
    kv = simplices.shape[0]
    const = isinstance(f, np.ndarray) or f.constant
    for start in range(0, simplices.shape[1], _CHUNK):
        s = simplices[:, start:start + _CHUNK]
        V = nodes[:, s]                                       # (dim, kv, ns)
        meas = _measure(V)
        if const:
            val = f if isinstance(f, np.ndarray) else np.array([float(x) for x in f.values])
            contrib = (scale * val[:, None, None] * (meas / kv)[None, None, :]) * np.ones((1, kv, 1))
        else:
            lam, w = simplex_rule(kv - 1)
            X = np.einsum("dkf,qk->dfq", V, lam)               # (dim, ns, q)
            vals = evaluate(f, X, what)
            contrib = scale * np.einsum("cfq,q,qk->ckf", vals, w, lam) * meas[None, None, :]
        for c in range(contrib.shape[0]):
            out[c] += np.bincount(s.ravel(), weights=contrib[c].ravel(), minlength=n)


def nodal_forces(spec: LoadSpec, nodes: np.ndarray, cells: np.ndarray, sides: dict[str, np.ndarray],
                 scale: float = 1.0) -> np.ndarray:
    """Consistent P1 nodal forces (dim, n), reference frame, times ``scale``: side tractions (Gauss rule of
    :func:`simplex_rule`; constants exactly), the remote stress sigma.n on every side without a support, and
    the body force over the cells (constants exactly: volume / (dim + 1) per node). InputError when an
    expression is not finite on its side (or in the body)."""
    dim, n = nodes.shape
    F = np.zeros((dim, n))
    stress = spec.stress
    with np.errstate(all="ignore"):
        for side in SIDES[dim]:
            s = spec.side(side)
            if s.traction is not None:
                integrate(F, nodes, sides[side], s.traction, scale, f"on the {side} side")
            if stress is not None and s.support == "free":
                integrate(F, nodes, sides[side], stress @ outward_normal(side, dim), scale, f"on the {side} side")
        if spec.body_force is not None:
            integrate(F, nodes, np.asarray(cells), spec.body_force, scale, "in the body")
    return F


def dof_numbering(mask: np.ndarray) -> np.ndarray:
    """node_dofs (dim, n) int64: the index of component c of node i among the free unknowns (numbered node by
    node, component by component: unknown dim i + c before the fixed ones are dropped), -1 where ``mask``
    (dim, n) fixes it."""
    free = ~np.asarray(mask, dtype=bool).T.ravel()
    idx = np.cumsum(free) - 1
    return np.where(free, idx, -1).reshape(mask.shape[1], mask.shape[0]).T.copy()


def face_pressure_forces(upper: np.ndarray, lower: np.ndarray, normals: np.ndarray, weights: np.ndarray,
                         pressure: np.ndarray, n_nodes: int) -> np.ndarray:
    """Nodal forces (dim, n_nodes) of a pressure p on both faces of defects (lumped with the interface
    term's nodal weights w): p > 0 pushes the faces apart, the "+" copy gets +p w nu, the "-" copy -p w nu
    (nu the normal, pointing to the "+" face; units: p stress, w length (2D) or area (3D))."""
    dim = normals.shape[0]
    F = np.zeros((dim, n_nodes))
    f = normals * (np.asarray(pressure, float) * np.asarray(weights, float))[None, :]
    for c in range(dim):
        np.add.at(F[c], upper, f[c])
        np.add.at(F[c], lower, -f[c])
    return F
