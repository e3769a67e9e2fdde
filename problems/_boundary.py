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
:func:`check_balance`, :func:`face_pressure_forces`, :func:`parse_scalar` (a per-defect
``face_pressure``).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from itertools import combinations
from typing import Any

import numpy as np
import scipy.linalg

from dualfem.core.errors import InputError
from dualfem.core.expressions import Expression, compile_expression

SIDES: dict[int, tuple[str, ...]] = {2: ("left", "right", "bottom", "top"),
                                     3: ("left", "right", "front", "back", "bottom", "top")}
SUPPORTS = ("clamp", "roller", "free")
#: the scene keys of this module (``face_pressure`` is a key of each defect)
KEYS = ("boundary", "body_force", "remote_stress")
TABLE_KEYS = ("side", "support", "traction")
VARIABLES: dict[int, tuple[str, ...]] = {2: ("x", "y"), 3: ("x", "y", "z")}
#: relative tolerance of a node lying on a side (of the largest box length)
SIDE_RTOL = 1e-9
#: the rigid-body completion must be at least this well conditioned (smallest / largest singular value)
MIN_CONDITION = 1e-3
#: net force / moment of loads on a body whose supports leave rigid motions free, relative to the loads
BALANCE_RTOL = 1e-8
#: cells per chunk when a body-force expression is integrated
_CHUNK = 20_000


def side_axis(side: str, dim: int) -> tuple[int, bool]:
    """(the coordinate axis normal to ``side``, whether the side is at the box's far end)."""
    k = SIDES[dim].index(side)
    return k // 2, bool(k % 2)


def outward_normal(side: str, dim: int) -> np.ndarray:
    """The outward unit normal (dim,) of ``side`` in the reference frame."""
    axis, far = side_axis(side, dim)
    n = np.zeros(dim)
    n[axis] = 1.0 if far else -1.0
    return n


def box_lengths(params: dict, dim: int) -> tuple[float, ...]:
    """The box's lengths along x, y (, z): (width, height) in 2D, (width, depth, height) in 3D."""
    return (float(params["width"]), float(params["height"])) if dim == 2 else \
        (float(params["width"]), float(params["depth"]), float(params["height"]))


# --------------------------------------------------------------------------- the typed keys
@dataclass(frozen=True)
class Field:
    """A vector (or scalar: one component) field given by numbers and/or expressions in x, y (, z).

    ``values``: the scene's values (floats, or expression texts), which define equality; ``key``: the
    scene key in messages. Call it with coordinates X (dim, ...) to get (ncomp, ...).
    """

    key: str
    values: tuple[float | str, ...]
    dim: int
    compiled: tuple[Expression | float, ...] = field(compare=False, repr=False, default=())

    @property
    def constant(self) -> bool:
        return all(not isinstance(v, str) for v in self.values)

    def __call__(self, X: np.ndarray) -> np.ndarray:
        shape = X.shape[1:]
        out = np.empty((len(self.values),) + shape)
        for c, g in enumerate(self.compiled):
            out[c] = g(*X) if isinstance(g, Expression) else g
        return out

    def label(self) -> list:
        return list(self.values)


@dataclass(frozen=True)
class Side:
    """One ``[[boundary]]`` table: the side, its support and its traction (None: none)."""

    side: str
    support: str = "free"
    traction: Field | None = None


@dataclass(frozen=True)
class LoadSpec:
    """The supports and loads of a scene (see the module docstring); ``stress`` as nested tuples."""

    dim: int
    box: tuple[float, ...]
    sides: tuple[Side, ...] = ()
    body_force: Field | None = None
    remote_stress: tuple[tuple[float, ...], ...] | None = None

    def side(self, name: str) -> Side:
        """The table of side ``name`` (a free, unloaded one if not listed)."""
        for s in self.sides:
            if s.side == name:
                return s
        return Side(name)

    @property
    def has_support(self) -> bool:
        return any(s.support != "free" for s in self.sides)

    @property
    def stress(self) -> np.ndarray | None:
        return None if self.remote_stress is None else np.array(self.remote_stress, dtype=float)

    def label(self) -> str:
        """A compact text of the keys (for ``QP.params`` and cache keys)."""
        parts = [f"{{side: {s.side}, support: {s.support}"
                 + (f", traction: {s.traction.label()}" if s.traction else "") + "}" for s in self.sides]
        out = f"boundary: [{', '.join(parts)}]"
        if self.body_force is not None:
            out += f", body_force: {self.body_force.label()}"
        if self.remote_stress is not None:
            out += f", remote_stress: {[list(r) for r in self.remote_stress]}"
        return out


# --------------------------------------------------------------------------- parsing
def _json(key: str, value: Any, form: str) -> Any:
    """A TOML value as is; a string (``--set``) read as JSON (a list or table), else left a string."""
    if isinstance(value, str):
        text = value.strip()
        if text[:1] in "[{":
            try:
                return json.loads(text)
            except ValueError:
                raise InputError(f"{key} must be {form} (from --set: JSON), got {value!r}") from None
    return value


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def _sample(box: tuple[float, ...], side: str | None, k: int = 7) -> np.ndarray:
    """Points (dim, k^(dim-1 or dim)) on a side of the box (or in the whole box when side is None)."""
    dim = len(box)
    axes = [np.linspace(0.0, L, k) for L in box]
    if side is not None:
        axis, far = side_axis(side, dim)
        axes[axis] = np.array([box[axis] if far else 0.0])
    grid = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grid])


def parse_field(value: Any, key: str, dim: int, ncomp: int, box: tuple[float, ...], side: str | None) -> Field:
    """A vector of ``ncomp`` numbers or expression strings in x, y (, z) (a scalar when ncomp = 1 may be
    given bare); each expression is checked by the sandbox and must be finite on ``side`` (the whole
    box when None). InputError naming ``key``."""
    names = ", ".join(VARIABLES[dim])
    form = (f"a vector of {ncomp} numbers or expressions in {names}" if ncomp > 1 else
            f"a number or an expression in {names}")
    v = _json(key, value, form)
    if ncomp == 1 and (_is_number(v) or isinstance(v, str)):
        v = [v]
    if not isinstance(v, (list, tuple)) or len(v) != ncomp:
        got = f" ({len(v)} components)" if isinstance(v, (list, tuple)) else ""
        raise InputError(f"{key} must be {form}, got {value!r}{got}")
    values, compiled = [], []
    where = "in the body" if side is None else f"on the {side} side"
    for c, item in enumerate(v):
        ckey = key if ncomp == 1 else f"{key}[{c}]"
        if _is_number(item):
            f = float(item)
            if not math.isfinite(f):
                raise InputError(f"{ckey} must be finite, got {item!r}")
            values.append(f)
            compiled.append(f)
        elif isinstance(item, str) and item.strip():
            expr = compile_expression(item, parameter=ckey, variables=VARIABLES[dim],
                                      hint=f"give {form}")
            if not np.all(np.isfinite(expr(*_sample(box, side)))):
                raise InputError(f"{ckey} = {item!r} gives NaN or infinite values {where}; it must be finite there")
            values.append(expr.text)
            compiled.append(expr)
        else:
            raise InputError(f"{ckey} must be a number or an expression in {names} (a string), got {item!r}")
    return Field(key, tuple(values), dim, tuple(compiled))


def parse_scalar(value: Any, key: str, dim: int, box: tuple[float, ...]) -> Field:
    """A scalar field (e.g. a defect's ``face_pressure``): a number or an expression in x, y (, z),
    finite in the box."""
    return parse_field(value, key, dim, 1, box, None)


def _parse_stress(value: Any, dim: int) -> tuple[tuple[float, ...], ...]:
    form = (f"a symmetric {dim}x{dim} tensor of finite numbers "
            + ("[[sxx, sxy], [sxy, syy]]" if dim == 2 else "[[sxx, sxy, sxz], [sxy, syy, syz], [sxz, syz, szz]]"))
    v = _json("remote_stress", value, form)
    if not (isinstance(v, (list, tuple)) and len(v) == dim
            and all(isinstance(r, (list, tuple)) and len(r) == dim and all(_is_number(x) for x in r) for r in v)):
        raise InputError(f"remote_stress must be {form}, got {value!r}")
    s = np.array(v, dtype=float)
    if not np.all(np.isfinite(s)):
        raise InputError(f"remote_stress must be {form}: got non-finite entries {value!r}")
    if np.abs(s - s.T).max() > 1e-12 * np.abs(s).max():
        raise InputError(f"remote_stress must be {form}: it is not symmetric, got {value!r}")
    s = 0.5 * (s + s.T)
    return tuple(tuple(float(x) for x in r) for r in s)


def _parse_table(k: int, tab: Any, dim: int, box: tuple[float, ...]) -> Side:
    key = f"boundary[{k}]"
    if not isinstance(tab, dict):
        raise InputError(f"{key} must be a table with side, support and/or traction, got {tab!r}")
    unknown = sorted(set(tab) - set(TABLE_KEYS))
    if unknown:
        raise InputError(f"{key}: unknown key {unknown[0]!r}; allowed: {', '.join(TABLE_KEYS)}")
    side = tab.get("side")
    if side not in SIDES[dim]:
        extra = " (front and back are sides of a 3D body)" if dim == 2 and side in ("front", "back") else ""
        raise InputError(f"{key}.side must be one of {', '.join(SIDES[dim])}{extra}, got {side!r}")
    if "support" not in tab and "traction" not in tab:
        raise InputError(f"{key} (side {side}) needs a support ({', '.join(SUPPORTS)}) and/or a traction")
    support = tab.get("support", "free")
    if support not in SUPPORTS:
        raise InputError(f"{key}.support must be one of {', '.join(SUPPORTS)}, got {support!r}")
    traction = None
    if "traction" in tab:
        if support == "clamp":
            raise InputError(f"{key}: a clamped side carries no traction (every component is fixed); "
                             f"drop traction or use support = roller or free")
        traction = parse_field(tab["traction"], f"{key}.traction", dim, dim, box, side)
    return Side(side, support, traction)


def parse_loads(params: dict, dim: int) -> LoadSpec | None:
    """The keys ``boundary``, ``body_force``, ``remote_stress`` of ``params`` as a :class:`LoadSpec`, or
    None when none is given (None / empty: the problem's legacy supports and loads apply).

    ``params`` holds validated box lengths (``width``, ``height``; ``depth`` in 3D). InputError naming
    the key (``boundary[2].traction``, ``remote_stress``, ...) and the allowed values.
    """
    box = box_lengths(params, dim)
    tables = _json("boundary", params.get("boundary"), "a list of tables")
    bf, rs = params.get("body_force"), params.get("remote_stress")
    if isinstance(bf, str) and not bf.strip():
        bf = None
    if isinstance(rs, str) and not rs.strip():
        rs = None
    empty = tables is None or (isinstance(tables, (list, tuple)) and len(tables) == 0)
    if empty and bf is None and rs is None:
        return None
    if empty:
        tables = []
    if not isinstance(tables, (list, tuple)):
        raise InputError(f"boundary must be a list of tables ([[boundary]] in TOML) with side, support and/or "
                         f"traction; got {tables!r}")
    if len(tables) > len(SIDES[dim]):
        raise InputError(f"boundary: {len(tables)} tables for {len(SIDES[dim])} sides; each side at most once")
    sides: list[Side] = []
    for k, tab in enumerate(tables):
        s = _parse_table(k, tab, dim, box)
        if any(o.side == s.side for o in sides):
            raise InputError(f"boundary[{k}].side = {s.side!r} is given twice; each side at most once")
        sides.append(s)
    stress = None if rs is None else _parse_stress(rs, dim)
    if stress is not None:
        for k, s in enumerate(sides):
            if s.traction is not None and s.support == "free":
                raise InputError(f"boundary[{k}].traction on the {s.side} side and remote_stress both load that "
                                 f"side: remote_stress applies sigma.n on every side without a support; drop "
                                 f"one of them")
    body = None if bf is None else parse_field(bf, "body_force", dim, dim, box, None)
    return LoadSpec(dim, box, tuple(sides), body, stress)


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
    mask = _support_mask(spec, nodes.shape[1], sides)
    nm = 3 if spec.dim == 2 else 6
    comp, idx = np.nonzero(mask)
    if idx.size == 0:
        return np.eye(nm)
    centre, length = _frame(nodes)
    R = _modes(nodes[:, idx], comp, centre, length)
    w, V = np.linalg.eigh(R.T @ R)
    return V[:, w <= 1e-10 * w.max()]


def _candidates(nodes: np.ndarray) -> np.ndarray:
    """Extreme nodes: the maximisers of s . x for s in {-1, 0, 1}^dim \\ {0} (vertices of the hull), distinct."""
    dim = nodes.shape[0]
    dirs = [np.array(s, float) for s in np.ndindex(*(3,) * dim)]
    dirs = [d - 1 for d in dirs if np.any(d != 1)]
    dirs.sort(key=lambda d: (-int(np.count_nonzero(d)), tuple(d)))     # corners first
    ids = [int(np.argmax(d @ nodes)) for d in dirs]
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
    mask = _support_mask(spec, nodes.shape[1], sides)
    N = free_modes(spec, nodes, sides)
    k = N.shape[1]
    if k == 0:
        return mask
    dim = spec.dim
    cand = _candidates(nodes)
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
    N = free_modes(spec, nodes, sides)
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


def _integrate(out: np.ndarray, nodes: np.ndarray, simplices: np.ndarray, f: Field | np.ndarray, scale: float,
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
            try:
                vals = f(X)
            except InputError:
                raise
            except Exception as exc:                           # noqa: BLE001 - an expression that breaks
                raise InputError(f"{f.key} cannot be evaluated {what}: {type(exc).__name__}: {exc}") from None
            if not np.all(np.isfinite(vals)):
                raise InputError(f"{f.key} gives NaN or infinite values {what}; it must be finite there")
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
                _integrate(F, nodes, sides[side], s.traction, scale, f"on the {side} side")
            if stress is not None and s.support == "free":
                _integrate(F, nodes, sides[side], stress @ outward_normal(side, dim), scale, f"on the {side} side")
        if spec.body_force is not None:
            _integrate(F, nodes, np.asarray(cells), spec.body_force, scale, "in the body")
    return F


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
