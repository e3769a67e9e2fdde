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


@dataclass(frozen=True)
class GeometryPart:
    """The mesh of a finite-element QP; ``node_dofs[c, i]`` is the unknown of component c of node i (-1: fixed).

    ``node_dofs`` has one row per field component: ``dim`` rows for displacements, one for a
    scalar field (a membrane's deflection)."""

    dim: int
    nodes: np.ndarray
    cells: np.ndarray
    node_dofs: np.ndarray

    @classmethod
    def make(cls, nodes, cells, node_dofs, dim: int | None = None) -> GeometryPart:
        X = np.asarray(nodes, dtype=float)
        d = int(X.shape[0]) if dim is None and X.ndim == 2 else int(dim or 0)
        return cls(d, X, _int_array(cells, "geometry.cells"), _int_array(node_dofs, "geometry.node_dofs"))

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
        if t.ndim != 2 or t.shape[0] != self.dim + 1:
            raise InputError(f"geometry.cells must have shape ({self.dim + 1}, n_cells), got {t.shape}")
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
