"""Typed optional parts of a :class:`dualfem.core.qp.QP`: what algorithms may read beyond (K, F, B, weights).

A problem plugin provides the parts it can; each part is validated against the QP when the QP is
constructed (:meth:`validate`, raising :class:`~dualfem.core.errors.InputError` naming the part and
the field), so a plugin that gets a shape or an index wrong fails at once instead of making an
algorithm silently fall back. Algorithms read these fields, never ``QP.params`` (write-only
provenance) and never ``QP.maps`` (problem-specific extras for post-processing).

==============  ==================================================================================
``local``       ``K = K_fixed + K_param`` with ``K_param`` (the 1/delta interface term) and ``B``
                supported on the unknowns ``dofs`` only: a factorization of ``K_fixed`` is reused
                across delta, r, loads and solvers (:mod:`dualfem.numerics.linalg`)
``shift``       the user's unknowns are ``x + shift.x`` and the user's objective is
                ``Pi(x) + shift.objective`` (a QP file with ``h != 0``, an obstacle gap)
``geometry``    the mesh: ``dim`` (2 or 3), ``nodes`` (dim, n_nodes), ``cells`` (dim + 1, n_cells:
                triangles or tetrahedra), ``node_dofs`` (components, n_nodes; -1 = fixed)
``units``       the scene's Young's modulus ``E`` (stress units) and length scale ``length`` (the
                body's width), for scale-free parameter rules such as uzawa's ``r_rule="scaled"``
``material``    ``E``, ``nu`` and ``plane`` of the elastic body, for stresses in post-processing
``interface``   the defect interface: node pairs and their unknowns, normals and tangent frames,
                nodal weights, defect ids, front/tips, faces (3D), per-node delta, the jump operator
                (:class:`InterfacePart`; every per-node array (m, ...), 2D and 3D alike)
==============  ==================================================================================
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from dualfem.core.errors import InputError


def _int_array(a, what: str) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype.kind not in "iu":
        if a.size == 0:
            return a.astype(np.int64)
        raise InputError(f"{what} must hold integers, got dtype {a.dtype}")
    return a.astype(np.int64, copy=False)


def _finite(a: np.ndarray, what: str) -> None:
    if a.dtype.kind not in "iuf":
        raise InputError(f"{what} must be real numbers, got dtype {a.dtype}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{what} contains NaN or infinite entries")


@dataclass(frozen=True)
class LocalPart:
    """``K = K_fixed + K_param``: ``K_param`` and ``B`` act on the unknowns ``dofs`` only.

    ``K_fixed`` (n x n, symmetric, positive definite after the supports) does not depend on delta,
    r or the load. ``dofs``: sorted unique indices into x.
    """

    K_fixed: sp.csc_matrix
    dofs: np.ndarray

    @classmethod
    def make(cls, K_fixed, dofs) -> LocalPart:
        """Normalised once: K_fixed as float CSC (the object itself when it already is one), dofs as sorted int64."""
        Kf = K_fixed if sp.issparse(K_fixed) and K_fixed.format == "csc" and K_fixed.dtype == float \
            else sp.csc_matrix(K_fixed, dtype=float)
        d = _int_array(np.asarray(dofs).ravel(), "local.dofs")
        if d.size > 1 and np.any(np.diff(d) <= 0):
            d = np.unique(d)
        return cls(Kf, d)

    def validate(self, K: sp.spmatrix, B: sp.csr_matrix) -> None:
        """Shapes, indices in range, B supported on ``dofs`` (K - K_fixed is checked by the reduction)."""
        n = K.shape[0]
        if self.K_fixed.shape != (n, n):
            raise InputError(f"local.K_fixed must have shape ({n}, {n}) like K, got {self.K_fixed.shape}")
        _finite(self.K_fixed.data, "local.K_fixed")
        d = self.dofs
        if d.size and (d[0] < 0 or d[-1] >= n):
            raise InputError(f"local.dofs must lie in [0, {n}), got values in [{d.min()}, {d.max()}]")
        if B.nnz:
            outside = np.setdiff1d(np.unique(B.indices[B.data != 0]), d, assume_unique=True)
            if outside.size:
                raise InputError(f"B has entries on {outside.size} unknowns outside local.dofs "
                                 f"(e.g. unknown {int(outside[0])}): local.dofs must contain every column of B")


@dataclass(frozen=True)
class ShiftPart:
    """The user's unknowns are ``x + x_shift`` and the user's objective ``Pi(x) + objective``.

    Optional, the user's own data exactly as given (a QP file's ``-q`` and ``h``): ``load`` (length n,
    the user's problem is ``min 1/2 y'Ky - load'y``) and ``rhs`` (length m, ``B y >= rhs``). The evaluator
    certifies the answer in the user's unknowns against them; without them it uses ``F + K x`` and
    ``B x`` (what the QP itself implies, which lost the digits of the user's load that are below the
    rounding of ``K x`` for a large shift)."""

    x: np.ndarray
    objective: float = 0.0
    load: np.ndarray | None = None
    rhs: np.ndarray | None = None

    @classmethod
    def make(cls, x, objective=0.0, load=None, rhs=None) -> ShiftPart:
        return cls(np.asarray(x, dtype=float).ravel(), float(np.asarray(objective, dtype=float).reshape(-1)[0])
                   if np.size(objective) else 0.0,
                   None if load is None else np.asarray(load, dtype=float).ravel(),
                   None if rhs is None else np.asarray(rhs, dtype=float).ravel())

    def validate(self, n: int, m: int | None = None) -> None:
        if self.x.shape != (n,):
            raise InputError(f"shift.x must have length {n} (the number of unknowns), got {self.x.shape[0]}")
        _finite(self.x, "shift.x")
        if not np.isfinite(self.objective):
            raise InputError(f"shift.objective must be finite, got {self.objective!r}")
        if self.load is not None:
            if self.load.shape != (n,):
                raise InputError(f"shift.load must have length {n} (the number of unknowns), got {self.load.size}")
            _finite(self.load, "shift.load")
        if self.rhs is not None:
            if m is not None and self.rhs.shape != (m,):
                raise InputError(f"shift.rhs must have length {m} (the rows of B), got {self.rhs.size}")
            _finite(self.rhs, "shift.rhs")


#: the finite elements a :class:`GeometryPart` may carry
ELEMENTS = ("P1", "P2", "P2-quarter-point")
#: nodes of a quadratic simplex per dimension (vertices and mid-edge nodes)
QUADRATIC_NODES = {2: 6, 3: 10}


@dataclass(frozen=True)
class GeometryPart:
    """The mesh of a finite-element QP; ``node_dofs[c, i]`` is the unknown of component c of node i (-1: fixed).

    ``node_dofs`` has one row per field component: ``dim`` rows for displacements, one for a
    scalar field (a membrane's deflection). ``element``: ``"P1"`` (default: the field is linear on each cell,
    every node a vertex of ``cells``) or a quadratic element (``"P2"``, ``"P2-quarter-point"``: the nodes beyond
    the cells' vertices are mid-edge nodes, the field is quadratic on each cell; post-processing that assumes P1
    gradients refuses it, what shows vertex values on the linear cells may use it). ``cells`` (k, n_cells): the
    linear cells (k = dim + 1), or, with a quadratic element, the quadratic cells (k = 6 in 2D, 10 in 3D:
    the vertices, then the mid-edge nodes in VTK's order (0,1), (1,2), (0,2)(, (0,3), (1,3), (2,3)), as
    scikit-fem's P2 elements number them; :attr:`quadratic`), whose rows ``cells[:dim + 1]`` are the linear
    cells."""

    dim: int
    nodes: np.ndarray
    cells: np.ndarray
    node_dofs: np.ndarray
    element: str = "P1"

    @classmethod
    def make(cls, nodes, cells, node_dofs, dim: int | None = None) -> GeometryPart:
        X = np.asarray(nodes, dtype=float)
        d = int(X.shape[0]) if dim is None and X.ndim == 2 else int(dim or 0)
        return cls(d, X, _int_array(cells, "geometry.cells"), _int_array(node_dofs, "geometry.node_dofs"))

    @property
    def quadratic(self) -> bool:
        """The cells are quadratic (6 nodes per triangle, 10 per tetrahedron; a quadratic element only)."""
        return self.cells.ndim == 2 and self.cells.shape[0] == QUADRATIC_NODES.get(self.dim, -1)

    def validate(self, n: int) -> None:
        if self.dim not in (2, 3):
            raise InputError(f"geometry.dim must be 2 or 3, got {self.dim}")
        X, nd, t = self.nodes, self.node_dofs, self.cells
        if X.ndim != 2 or X.shape[0] != self.dim:
            raise InputError(f"geometry.nodes must have shape ({self.dim}, n_nodes), got {X.shape}")
        _finite(X, "geometry.nodes")
        nn = X.shape[1]
        if nd.ndim != 2 or nd.shape[1] != nn or nd.shape[0] < 1:
            raise InputError(f"geometry.node_dofs must have shape (components, {nn}), got {nd.shape}")
        if self.element not in ELEMENTS:
            raise InputError(f"geometry.element must be one of {', '.join(ELEMENTS)}, got {self.element!r}")
        rows = (self.dim + 1,) if self.element == "P1" else (self.dim + 1, QUADRATIC_NODES[self.dim])
        if t.ndim != 2 or t.shape[0] not in rows:
            raise InputError(f"geometry.cells must have shape ({' or '.join(map(str, rows))}, n_cells) for element "
                             f"{self.element!r}, got {t.shape}")
        if t.size and (t.min() < 0 or t.max() >= nn):
            raise InputError(f"geometry.cells must hold node indices in [0, {nn}), got [{t.min()}, {t.max()}]")
        free = nd[nd >= 0]
        if nd.size and nd.min() < -1:
            raise InputError(f"geometry.node_dofs must be -1 (fixed) or an unknown index, got {nd.min()}")
        if free.size and free.max() >= n:
            raise InputError(f"geometry.node_dofs must hold unknown indices in [0, {n}), got {free.max()}")
        if free.size and np.bincount(free, minlength=n).max() > 1:
            raise InputError("geometry.node_dofs names one unknown for two node components")


@dataclass(frozen=True)
class UnitsPart:
    """The scene's units: Young's modulus ``E`` (stress) and the length scale ``length`` (the body's width)."""

    E: float
    length: float

    def validate(self) -> None:
        for k in ("E", "length"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise InputError(f"units.{k} must be a finite number > 0, got {v!r}")


@dataclass(frozen=True)
class MaterialPart:
    """Isotropic linear elasticity of the body: Young's modulus ``E`` (stress units), Poisson's ratio
    ``nu`` and, in 2D, ``plane`` (``"strain"`` or ``"stress"``); for stresses in post-processing."""

    E: float
    nu: float
    plane: str = "strain"

    def validate(self) -> None:
        if not (isinstance(self.E, (int, float)) and np.isfinite(self.E) and self.E > 0):
            raise InputError(f"material.E must be a finite number > 0, got {self.E!r}")
        if not (isinstance(self.nu, (int, float)) and -1.0 < self.nu < 0.5):
            raise InputError(f"material.nu must lie in (-1, 0.5), got {self.nu!r}")
        if self.plane not in ("strain", "stress"):
            raise InputError(f"material.plane must be 'strain' or 'stress', got {self.plane!r}")


#: the ``maps`` keys the interface part answers for one release (2D layout of the normals: (2, m))
INTERFACE_MAPS = {"defect_upper": "upper", "defect_lower": "lower", "defect_id": "defect_id",
                  "defect_normals": "normals", "defect_tangents": "tangents", "defect_s": "s",
                  "defect_tips": "front", "defect_front": "front", "defect_front_id": "front_id",
                  "defect_faces": "faces", "defect_delta": "delta"}


def _frame(normals: np.ndarray) -> np.ndarray:
    """Unit tangents (m, dim - 1, dim) completing each unit normal to a right-handed orthonormal frame.

    2D: ``t = (n_1, -n_0)`` (the normal is the tangent turned by +90 degrees). 3D: ``t_1`` is the
    normalised ``n x e_k`` with ``e_k`` the coordinate axis least aligned with ``n``, ``t_2 = n x t_1``."""
    m, dim = normals.shape
    if dim == 2:
        return np.stack([normals[:, 1], -normals[:, 0]], axis=1)[:, None, :]
    axis = np.zeros((m, 3))
    axis[np.arange(m), np.argmin(np.abs(normals), axis=1)] = 1.0
    t1 = np.cross(normals, axis)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return np.stack([t1, np.cross(normals, t1)], axis=1)


@dataclass(frozen=True)
class InterfacePart:
    """The defect interface of a cut mesh: m constrained node pairs (row j of B is pair j), 2D and 3D alike.

    Every per-node array has one row per pair (shape (m, ...)):

    ``dim``: 2 or 3. ``upper``/``lower`` (m,): mesh node ids of the "+" and "-" copies; ``plus_dofs``/
    ``minus_dofs`` (m, dim): their unknowns (``geometry.node_dofs[:, upper].T``; never fixed);
    ``normals`` (m, dim): unit "+" normals (the "+" face is the side the normal points to);
    ``tangents`` (m, dim - 1, dim): unit tangents, with the normal an orthonormal frame (2D: the
    defect's direction of travel, ``(n_1, -n_0)``); ``weights`` (m,): nodal weights, a length in 2D and an
    area in 3D (``integral over the defect of phi ~ sum_j w_j phi_j``; equal to ``QP.weights``);
    ``defect_id`` (m,): which defect (from 0); ``front``/``front_id`` (k,): the single (not doubled) nodes
    bounding each defect and their defect (2D: its two tips, first and last; 3D: its front);
    ``faces`` (n_faces, 3) or None: the defect triangles as node ids of the "-" face (3D);
    ``s`` (m,) or None: arc length from the defect's first tip (2D); ``delta`` (m,) or None: the defect's
    thickness at each node (length units; None when unknown, e.g. a QP file without it).

    Sign convention: the jump is ``[u] = u^+ - u^-``; the normal jump ``[u_nu] = nu . [u]`` is row j of B
    (``B x >= 0``: no interpenetration); :meth:`jump_operator` gives normal and tangential jumps.
    """

    dim: int
    upper: np.ndarray
    lower: np.ndarray
    plus_dofs: np.ndarray
    minus_dofs: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    weights: np.ndarray
    defect_id: np.ndarray
    front: np.ndarray
    front_id: np.ndarray
    faces: np.ndarray | None = None
    s: np.ndarray | None = None
    delta: np.ndarray | None = None

    @classmethod
    def make(cls, node_dofs, upper, lower, normals, weights, defect_id=None, *, tangents=None, front=None,
             front_id=None, faces=None, s=None, delta=None) -> InterfacePart:
        """From the mesh's ``node_dofs`` (dim, n_nodes) and the cut (normals (m, dim); tangents (m, dim - 1,
        dim), default :func:`_frame`; 2D ``front`` without ``front_id``: the tips, two per defect)."""
        nd = _int_array(node_dofs, "interface.node_dofs")
        up, lo = _int_array(upper, "interface.upper").ravel(), _int_array(lower, "interface.lower").ravel()
        nrm = np.asarray(normals, dtype=float)
        dim = int(nd.shape[0])
        if nrm.ndim == 1 and nrm.size == 0:
            nrm = nrm.reshape(0, dim)
        tng = _frame(nrm) if tangents is None and nrm.ndim == 2 and nrm.shape[1] == dim else \
            np.asarray(tangents, dtype=float)
        fr = np.zeros(0, np.int64) if front is None else _int_array(front, "interface.front").ravel()
        fid = np.repeat(np.arange(fr.size // 2), 2) if front_id is None else _int_array(front_id, "interface.front_id")
        return cls(dim, up, lo, nd[:, up].T, nd[:, lo].T, nrm, tng, np.asarray(weights, dtype=float).ravel(),
                   np.zeros(up.size, np.int64) if defect_id is None else _int_array(defect_id, "interface.defect_id"),
                   fr, fid.ravel(), None if faces is None else _int_array(faces, "interface.faces"),
                   None if s is None else np.asarray(s, dtype=float).ravel(),
                   None if delta is None else np.asarray(delta, dtype=float).ravel())

    @property
    def m(self) -> int:
        """The number of node pairs (rows of B)."""
        return int(self.upper.size)

    def validate(self, n: int, m: int, geometry: GeometryPart | None, weights: np.ndarray) -> None:
        """Shapes, finiteness, unit normals and frames, indices in range, the dofs those of ``geometry``."""
        d = self.dim
        if d not in (2, 3):
            raise InputError(f"interface.dim must be 2 or 3, got {d}")
        shapes = {"upper": (m,), "lower": (m,), "plus_dofs": (m, d), "minus_dofs": (m, d), "normals": (m, d),
                  "tangents": (m, d - 1, d), "weights": (m,), "defect_id": (m,),
                  "front_id": self.front.shape, "s": (m,), "delta": (m,), "faces": (-1, 3)}
        for k, want in shapes.items():
            a = getattr(self, k)
            if a is not None and (a.shape != want if want[0] != -1 else a.ndim != 2 or a.shape[1] != 3):
                raise InputError(f"interface.{k} must have shape {want} (m = {m} rows of B), got {a.shape}")
        for k in ("normals", "tangents", "weights", "s", "delta"):
            if getattr(self, k) is not None:
                _finite(getattr(self, k), f"interface.{k}")
        frame = np.concatenate([self.normals[:, None, :], self.tangents], axis=1)
        if m and np.abs(np.einsum("jak,jbk->jab", frame, frame) - np.eye(d)).max() > 1e-8:
            raise InputError("interface.normals and interface.tangents must be an orthonormal frame at every node")
        if not np.array_equal(self.weights, weights):
            raise InputError("interface.weights must equal the QP's weights")
        if self.delta is not None and np.any(self.delta <= 0):
            raise InputError("interface.delta must be > 0")
        if self.defect_id.size and self.defect_id.min() < 0:
            raise InputError("interface.defect_id must be >= 0")
        for k in ("plus_dofs", "minus_dofs"):
            a = getattr(self, k)
            if a.size and (a.min() < 0 or a.max() >= n):
                raise InputError(f"interface.{k} must hold unknown indices in [0, {n}) (a defect node is never "
                                 f"fixed), got [{a.min()}, {a.max()}]")
        if geometry is None:
            raise InputError("an interface part needs the QP's geometry (the mesh its node ids refer to)")
        nn = geometry.nodes.shape[1]
        for k in ("upper", "lower", "front", "faces"):
            a = getattr(self, k)
            if a is not None and a.size and (a.min() < 0 or a.max() >= nn):
                raise InputError(f"interface.{k} must hold node ids in [0, {nn}), got [{a.min()}, {a.max()}]")
        nd = geometry.node_dofs
        if d != geometry.dim or nd.shape[0] != d or not (np.array_equal(nd[:, self.upper].T, self.plus_dofs)
                                                       and np.array_equal(nd[:, self.lower].T, self.minus_dofs)):
            raise InputError("interface.plus_dofs/minus_dofs must be geometry.node_dofs at the upper/lower nodes")

    # ------------------------------------------------------------------ jumps
    def jump_operator(self, n: int) -> sp.csr_matrix:
        """The (dim m) x n jump operator, rows in blocks of m: block 0 the normal jumps ``nu_j . [u]_j``
        (= B), block 1 (and 2 in 3D) the tangential jumps ``t_j . [u]_j`` (length units)."""
        m, d = self.m, self.dim
        frame = np.concatenate([self.normals[:, None, :], self.tangents], axis=1)      # (m, d, d)
        rows = np.broadcast_to((np.arange(d)[:, None] * m + np.arange(m)[None, :]).T[:, :, None], (m, d, d))
        cols_p = np.broadcast_to(self.plus_dofs[:, None, :], (m, d, d))
        cols_m = np.broadcast_to(self.minus_dofs[:, None, :], (m, d, d))
        return sp.csr_matrix((np.r_[frame.ravel(), -frame.ravel()],
                              (np.r_[rows.ravel(), rows.ravel()], np.r_[cols_p.ravel(), cols_m.ravel()])),
                             shape=(d * m, n))

    def jumps(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(normal jumps (m,), tangential jumps (m, dim - 1)) of the unknowns ``x``: ``[u] = u^+ - u^-``."""
        x = np.asarray(x, dtype=float)
        j = x[self.plus_dofs] - x[self.minus_dofs]
        return np.einsum("jk,jk->j", j, self.normals), np.einsum("jak,jk->ja", self.tangents, j)

    # ------------------------------------------------------------ old maps
    def legacy_maps(self) -> dict[str, np.ndarray]:
        """The ``maps``/``map_*`` arrays of earlier releases (what QP files hold): 2D normals and tangents
        as (2, m), tips as ``defect_tips``; 3D normals (m, 3), faces (3, n_faces), ``defect_front(_id)``."""
        out = {"defect_upper": self.upper, "defect_lower": self.lower, "defect_id": self.defect_id}
        if self.dim == 2:
            out.update(defect_tips=self.front, defect_normals=np.ascontiguousarray(self.normals.T),
                       defect_tangents=np.ascontiguousarray(self.tangents[:, 0, :].T))
            if self.s is not None:
                out["defect_s"] = self.s
        else:
            out.update(defect_normals=self.normals, defect_front=self.front, defect_front_id=self.front_id)
            if self.faces is not None:
                out["defect_faces"] = np.ascontiguousarray(self.faces.T)
        if self.delta is not None:
            out["defect_delta"] = self.delta
        return out

    @classmethod
    def from_maps(cls, maps: dict, geometry: GeometryPart, weights: np.ndarray) -> InterfacePart | None:
        """The part from the old ``maps`` keys (a QP file's ``map_*`` arrays, checked by
        :func:`dualfem.core.qpfile.check_maps`), or None without ``defect_upper``/``defect_lower`` or when the
        mesh's ``node_dofs`` is not (dim, n_nodes). A 2D file without ``defect_normals`` (one straight
        defect) takes ``normal`` (default (0, 1)) and ``tangent`` at every node."""
        nd, dim = geometry.node_dofs, geometry.dim
        if "defect_upper" not in maps or "defect_lower" not in maps or nd.shape != (dim, geometry.nodes.shape[1]) \
                or (dim == 3 and "defect_normals" not in maps):
            return None
        up = np.asarray(maps["defect_upper"]).ravel()
        m = up.size
        nrm = np.asarray(maps.get("defect_normals", np.zeros((0, dim))), dtype=float)
        tng = None
        if dim == 2:
            if "defect_normals" in maps:
                nrm = nrm.T
            else:
                nrm = np.tile(np.asarray(maps.get("normal", (0.0, 1.0)), dtype=float).ravel(), (m, 1))
            t = maps.get("defect_tangents")
            if t is None and "tangent" in maps:
                t = np.tile(np.asarray(maps["tangent"], dtype=float).ravel(), (m, 1)).T
            tng = None if t is None else np.asarray(t, dtype=float).T[:, None, :]
        faces = maps.get("defect_faces")
        return cls.make(nd, up, maps["defect_lower"], nrm, weights, maps.get("defect_id"), tangents=tng,
                        front=maps.get("defect_tips" if dim == 2 else "defect_front"),
                        front_id=None if dim == 2 else maps.get("defect_front_id"),
                        faces=None if faces is None else np.asarray(faces).T, s=maps.get("defect_s"),
                        delta=maps.get("defect_delta"))
