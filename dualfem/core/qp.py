"""The QP that every solver receives.

    minimize    1/2 x' K x - F' x
    subject to  B x >= 0                      (one row per constrained defect node)

Conventions (stated once, used everywhere):

* ``x``: displacements of the free degrees of freedom (length units of the scene).
* ``B``: row j is the normal jump ``[u_nu]_j = nu . (u_j^+ - u_j^-)`` at defect node j; it is
  purely geometric (entries are components of the unit normal), so ``B x`` is a length.
  ``B x >= 0`` means no interpenetration.
* ``weights``: trapezoid weight w_j of defect node j (a length): ``integral over gamma0 of
  phi ~ sum_j w_j phi_j``.
* **Multipliers** ``mu`` (``Solution.multipliers``): nodal contact forces, ``mu >= 0`` in
  compression, with ``K x - F = B' mu`` at the solution. Units: force per unit thickness
  (stress x length, e.g. MPa.mm). The paper's pressure ``l(x) = -sigma_nu + [u_nu]/delta``
  (units of stress) is ``pressure = mu / weights`` (:meth:`QP.pressure`).

Optional structure lets fast solvers reuse work: ``K = K_fixed + K_param`` where ``K_param``
(the 1/delta interface term) touches only ``local_dofs``, and ``B`` touches only ``local_dofs``
too. ``K_fixed`` does not depend on delta, r or the load, so a factorization of it is reused
across all of them.
"""
from __future__ import annotations

import dataclasses
import hashlib
import warnings
from dataclasses import InitVar, dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from dualfem.core.constraints import Constraint, stack
from dualfem.core.errors import InputError
from dualfem.core.io import atomic_write
from dualfem.core.laws import SIGNORINI
from dualfem.core.parts import (
    INTERFACE_MAPS,
    GeometryPart,
    InterfacePart,
    LocalPart,
    MaterialPart,
    ShiftPart,
    UnitsPart,
)
from dualfem.core.qpfile import VECTOR_MAPS, check_maps, check_params, coo_from_arrays, export_matrix, read_arrays  # noqa: F401  (they lived here: still importable)

#: ``maps`` keys that became typed parts (read through ``maps`` with a DeprecationWarning for one release)
PROMOTED_MAPS = {"x_shift": ("shift", "x"), "objective_offset": ("shift", "objective"),
                 "nodes": ("geometry", "nodes"), "triangles": ("geometry", "cells"),
                 "node_dofs": ("geometry", "node_dofs"), **{k: ("interface", f) for k, f in INTERFACE_MAPS.items()}}


class Maps(dict):
    """``QP.maps``: problem-specific extra arrays (post-processing, export).

    The keys that became typed parts (:data:`PROMOTED_MAPS`) are still answered, from the part, with a
    DeprecationWarning (they will be removed from ``maps`` in the next release: read ``qp.shift``,
    ``qp.geometry`` instead); they are not stored twice and are not listed by iteration.
    """

    def __init__(self, data=(), promoted: dict | None = None):
        super().__init__(data)
        self._promoted = dict(promoted or {})

    def _old(self, key):
        part, fld = PROMOTED_MAPS[key]
        warnings.warn(f"qp.maps[{key!r}] is deprecated: read qp.{part}.{fld}", DeprecationWarning, stacklevel=3)
        return self._promoted[key]

    def __getitem__(self, key):
        if key in self._promoted and not dict.__contains__(self, key):
            return self._old(key)
        return super().__getitem__(key)

    def get(self, key, default=None):
        if key in self._promoted and not dict.__contains__(self, key):
            return self._old(key)
        return super().get(key, default)

    def __contains__(self, key) -> bool:
        return dict.__contains__(self, key) or key in self._promoted

    def legacy(self) -> dict:
        """Every array, the typed parts' under their old keys too, as a plain dict (no warning): what a QP
        file holds as ``map_*`` arrays."""
        return {**self._promoted, **self}


def _parts_from_maps(maps: dict, n: int) -> tuple[dict, dict]:
    """Split an old-style ``maps`` into (remaining extras, typed parts found in it)."""
    rest = {k: v for k, v in maps.items() if k not in PROMOTED_MAPS or k in INTERFACE_MAPS}   # see QP._interface
    parts: dict = {}
    if "x_shift" in maps and np.shape(maps["x_shift"]) == (n,):
        parts["shift"] = ShiftPart.make(maps["x_shift"], maps.get("objective_offset", 0.0))
    if all(k in maps for k in ("nodes", "triangles", "node_dofs")):
        X = np.asarray(maps["nodes"])
        if X.ndim == 2 and X.shape[0] in (2, 3):
            parts["geometry"] = GeometryPart.make(X, maps["triangles"], maps["node_dofs"])
    return rest, parts


@dataclass
class QP:
    """A convex QP ``min 1/2 x'Kx - F'x  s.t.  Bx >= 0`` in plain scipy.sparse / numpy data.

    Optional typed parts (:mod:`dualfem.core.parts`), validated here: ``local`` (``K_fixed`` and the
    local unknowns: ``K_fixed=``/``local_dofs=`` are a shorthand for it), ``shift``, ``geometry``,
    ``units``, ``material``, ``interface``. ``params``: write-only provenance (the scene's parameters; no
    algorithm reads it).
    ``maps``: problem-specific extras (defect node maps for post-processing and export).
    ``blocks``: constraint blocks beyond the Signorini block ``(B, weights)``
    (:class:`dualfem.core.constraints.Constraint`, each with its :mod:`law <dualfem.core.laws>`);
    :attr:`constraints` lists them all, the Signorini block first (today's QPs have only that one).
    ``store``: the owner of reusable derived data (the factorizations of ``K_fixed``: a
    :class:`dualfem.numerics.linalg.FactorStore`), set by the workspace that built the QP
    (:class:`dualfem.workspace.Workspace`: its QPs share one across deltas and loads); None = the QP
    gets a private one on first use, shared by every solver and the certificate working on it. Not part
    of the QP's value: excluded from equality, ``repr``, export, pickling and copies.
    """

    K: sp.csc_matrix
    F: np.ndarray
    B: sp.csr_matrix
    weights: np.ndarray | None = None
    K_fixed: InitVar[sp.spmatrix | None] = None
    local_dofs: InitVar[np.ndarray | None] = None
    name: str = "qp"
    params: dict = field(default_factory=dict)
    maps: dict = field(default_factory=dict)
    local: LocalPart | None = None
    shift: ShiftPart | None = None
    geometry: GeometryPart | None = None
    units: UnitsPart | None = None
    material: MaterialPart | None = None
    blocks: tuple[Constraint, ...] = ()
    interface: InterfacePart | None = None
    store: object | None = field(default=None, compare=False, repr=False)

    def __post_init__(self, K_fixed, local_dofs) -> None:
        self.K = self.K if sp.issparse(self.K) and self.K.format == "csc" and self.K.dtype == float \
            else sp.csc_matrix(self.K, dtype=float)
        self.F = np.asarray(self.F, dtype=float).ravel()
        self.B = sp.csr_matrix(self.B, dtype=float)
        n = self.K.shape[0]
        if self.K.shape != (n, n):
            raise InputError(f"K must be square, got shape {self.K.shape}")
        if self.F.shape != (n,):
            raise InputError(f"F must have length {n} (the size of K), got {self.F.shape[0]}")
        if self.B.shape[1] != n:
            raise InputError(f"B must have {n} columns (the size of K), got {self.B.shape[1]}")
        m = self.B.shape[0]
        if self.weights is None:
            self.weights = np.ones(m)
        self.weights = np.asarray(self.weights, dtype=float).ravel()
        if self.weights.shape != (m,):
            raise InputError(f"weights must have length {m} (rows of B), got {self.weights.shape[0]}")
        for nm, arr in (("K", self.K.data), ("F", self.F), ("B", self.B.data), ("weights", self.weights)):
            if not np.all(np.isfinite(arr)):
                raise InputError(f"{nm} contains NaN or infinite entries")
        if np.any(self.weights <= 0):
            raise InputError("weights must be > 0")
        self.blocks = tuple(self.blocks or ())
        for block in self.blocks:
            if not isinstance(block, Constraint):
                raise InputError(f"QP blocks must be dualfem.core.constraints.Constraint, got {type(block).__name__}")
            block.validate(n)
        self._init_parts(K_fixed, local_dofs)

    def _init_parts(self, K_fixed, local_dofs) -> None:
        n = self.K.shape[0]
        maps = dict(self.maps or {})
        if isinstance(self.maps, Maps):
            maps.update({k: v for k, v in self.maps._promoted.items() if k not in maps})
        rest, found = _parts_from_maps(maps, n)
        if "shift" in found and self.shift is None:
            if not isinstance(self.maps, Maps):
                warnings.warn("QP(maps={'x_shift': ...}) is deprecated: pass shift=ShiftPart.make(x, objective)",
                              DeprecationWarning, stacklevel=4)
            self.shift = found["shift"]
        if "geometry" in found and self.geometry is None:
            if not isinstance(self.maps, Maps):
                warnings.warn("QP(maps={'nodes', 'triangles', 'node_dofs'}) is deprecated: pass "
                              "geometry=GeometryPart.make(nodes, cells, node_dofs)", DeprecationWarning, stacklevel=4)
            self.geometry = found["geometry"]
        if K_fixed is not None or local_dofs is not None or self.local is None:
            Kf = K_fixed if K_fixed is not None else (self.local.K_fixed if self.local is not None else self.K)
            dofs = local_dofs if local_dofs is not None else (
                self.local.dofs if self.local is not None else np.unique(self.B.indices))
            self.local = LocalPart.make(Kf, dofs)
        self.local.validate(self.K, self.B)
        if self.shift is not None:
            self.shift.validate(n)
        if self.geometry is not None:
            self.geometry.validate(n)
        for part in (self.units, self.material):
            if part is not None:
                part.validate()
        rest = self._interface(rest)
        if self.interface is not None:
            self.interface.validate(n, self.B.shape[0], self.geometry, np.asarray(self.weights))
        promoted: dict[str, np.ndarray] = {}
        if self.shift is not None:
            promoted.update(x_shift=self.shift.x, objective_offset=np.array(self.shift.objective))
        if self.geometry is not None:
            g = self.geometry
            promoted.update(nodes=g.nodes, triangles=g.cells, node_dofs=g.node_dofs)
        if self.interface is not None:
            promoted.update(self.interface.legacy_maps())
        self.maps = Maps(rest, promoted)

    def _interface(self, rest: dict) -> dict:
        """The interface part from old-style defect ``maps`` keys (DeprecationWarning unless they came from a
        :class:`Maps`); returns ``rest`` without the keys the part answers for. Keys that do not make a valid
        part of this QP (another QP's maps: other rows of B) stay plain extras, unread, as they were."""
        if self.interface is None and self.geometry is not None:
            try:
                found = InterfacePart.from_maps(rest, self.geometry, np.asarray(self.weights))
                if found is not None:
                    found.validate(self.K.shape[0], self.B.shape[0], self.geometry, np.asarray(self.weights))
            except (InputError, IndexError, ValueError):
                found = None
            if found is not None and not isinstance(self.maps, Maps):
                warnings.warn("QP(maps={'defect_upper', ...}) is deprecated: pass "
                              "interface=InterfacePart.make(...)", DeprecationWarning, stacklevel=5)
            self.interface = found
        if self.interface is None:
            return rest
        return {k: v for k, v in rest.items() if k not in INTERFACE_MAPS}

    def __getstate__(self) -> dict:
        """Pickling and copies leave the store behind (a factorization is neither picklable nor the
        copy's: the copy gets a private store on first use)."""
        return {**self.__dict__, "store": None}

    # ---------------------------------------------------------------- sizes
    @property
    def n(self) -> int:
        """Number of unknowns."""
        return self.K.shape[0]

    @property
    def m(self) -> int:
        """Number of constraints (defect nodes)."""
        return self.B.shape[0]

    @property
    def constraints(self) -> tuple[Constraint, ...]:
        """Every constraint block: the Signorini block ``(B, weights)`` first, then :attr:`blocks`."""
        return (Constraint(self.B, self.weights, SIGNORINI), *self.blocks)  # type: ignore[arg-type]

    @property
    def G(self) -> sp.csr_matrix:
        """The operators of all blocks stacked (``B`` itself when the QP has only the Signorini block):
        ``K x - F = G' mu`` at the solution, mu the blocks' multipliers concatenated."""
        return self.B if not self.blocks else stack(self.constraints)

    @property
    def m_total(self) -> int:
        """Rows of all blocks: the length of a solution's multipliers (``m`` with one block)."""
        return self.B.shape[0] + sum(b.m for b in self.blocks)

    # -------------------------------------------------------------- helpers
    def energy(self, x: np.ndarray, Kx: np.ndarray | None = None) -> float:
        """Discrete potential energy Pi(x) = 1/2 x'Kx - F'x (``Kx``: the product K x, if known)."""
        return float(0.5 * x @ (self.K @ x if Kx is None else Kx) - self.F @ x)

    def pressure(self, multipliers: np.ndarray) -> np.ndarray:
        """Contact pressure l_j = mu_j / w_j (units of stress) from nodal multipliers."""
        return np.asarray(multipliers) / self.weights

    def key(self) -> str:
        """A hash of (K, F, B): equal keys mean the same QP."""
        h = hashlib.sha1()
        for a in (self.K.indptr, self.K.indices, self.K.data, self.F, self.B.indptr, self.B.indices, self.B.data):
            h.update(np.ascontiguousarray(a).tobytes())
        for b in self.blocks:                 # further blocks (none in today's QPs: their keys are unchanged)
            h.update(b.law.name.encode() + repr(b.law).encode())
            for a in (b.G.indptr, b.G.indices, b.G.data, b.weights):
                h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:16]

    def check(self, *, symmetric_tol: float = 1e-10) -> None:
        """Check symmetry of K and positive diagonal (cheap checks); raise InputError."""
        d = abs(self.K - self.K.T)
        scale = max(abs(self.K).max(), 1e-300)
        if d.nnz and d.max() > symmetric_tol * scale:
            raise InputError(f"K must be symmetric; max |K - K'| / max|K| = {d.max() / scale:.2e}")
        if np.any(self.K.diagonal() <= 0):
            raise InputError("K must be positive definite; it has a non-positive diagonal entry")

    # ---------------------------------------------------------------- export
    def to_dict(self) -> dict:
        """Plain arrays (for .npz/.mat); sparse matrices as CSC/CSR triplet arrays. A QP with blocks
        beyond the Signorini one has no file format yet: InputError (never an export that drops them)."""
        if self.blocks:
            raise InputError(f"QP {self.name!r} has constraint blocks beyond the Signorini one "
                             f"({', '.join(b.law.name for b in self.blocks)}): QP files hold only B")
        K = self.K.tocoo()
        B = self.B.tocoo()
        out = {
            "K_row": K.row, "K_col": K.col, "K_data": K.data, "K_shape": np.array(K.shape),
            "B_row": B.row, "B_col": B.col, "B_data": B.data, "B_shape": np.array(B.shape),
            "F": self.F, "weights": self.weights,
            "local_dofs": self.local.dofs if self.local is not None else np.zeros(0, np.int64),
            "name": np.array(self.name),
        }
        for k, v in self.params.items():
            if isinstance(v, (int, float, str)):
                out[f"param_{k}"] = np.array(v)
        maps = self.maps.legacy() if isinstance(self.maps, Maps) else self.maps
        for k, v in maps.items():            # the typed parts are written as the documented map_ arrays
            out[f"map_{k}"] = np.asarray(v)
        return out

    def save(self, path: str | Path) -> Path:
        """Write the QP to ``.npz`` or ``.mat`` atomically (write to a temp file, then rename)."""

        path = Path(path)
        data = self.to_dict()
        if path.suffix == ".npz":
            def write(tmp):
                with open(tmp, "wb") as fh:
                    np.savez_compressed(fh, **data)
        elif path.suffix == ".mat":
            import scipy.io

            data = {k: v for k, v in data.items() if v.dtype.kind != "U"}
            mat = {**data, "K": self.K, "B": self.B.tocsc(), "name": self.name}

            def write(tmp):
                scipy.io.savemat(tmp, mat, do_compression=True)
        else:
            raise InputError(f"output file must end in .npz or .mat, got {path.name!r}")
        atomic_write(path, write)
        return path

    @classmethod
    def load(cls, path: str | Path) -> QP:
        """Read a QP written by :meth:`save` (``.npz`` or ``.mat``) and validate it."""
        from dualfem.core.io import check_input_path

        path = check_input_path(Path(path), "QP file")
        if path.suffix not in (".npz", ".mat"):
            raise InputError(f"QP file must end in .npz or .mat, got {path.name!r}")
        where = f"QP file {str(path)!r}"
        try:
            d = read_arrays(path, where)    # declared sizes checked before anything is decompressed
        except InputError:
            raise
        except NotImplementedError as exc:  # scipy.io cannot read MATLAB v7.3 (HDF5) files
            raise InputError(f"cannot read QP file {str(path)!r}: {exc}; save it from MATLAB with "
                             f"save(..., '-v7') instead") from None
        except Exception as exc:  # noqa: BLE001 - corrupt file
            raise InputError(f"cannot read QP file {str(path)!r}: {exc}") from None
        try:
            F = np.asarray(d["F"]).ravel()
            if F.dtype.kind not in "iuf":
                raise InputError(f"array 'F' in {where} must be numeric, got dtype {F.dtype}")
            n = F.size
            if n == 0:
                raise InputError(f"array 'F' in {where} is empty: a QP needs at least one unknown (n >= 1)")
            w = None
            if "weights" in d:
                w = np.asarray(d["weights"]).ravel()
                if w.dtype.kind not in "iuf":
                    raise InputError(f"array 'weights' in {where} must be numeric, got dtype {w.dtype}")
            K, B = export_matrix(d, "K", where, n, n), export_matrix(d, "B", where, None if w is None else w.size, n)
        except InputError:
            raise
        except KeyError as exc:
            raise InputError(f"{where} lacks the array {exc.args[0]!r}") from None
        except ValueError as exc:
            raise InputError(f"{where} has inconsistent arrays: {exc}") from None
        maps = {k[4:]: v for k, v in d.items() if k.startswith("map_")}
        if path.suffix == ".mat":               # MATLAB keeps vectors as 1 x k matrices
            maps = {k: (v.ravel() if k in VECTOR_MAPS and np.ndim(v) == 2 and 1 in np.shape(v) else v)
                    for k, v in maps.items()}
        params = {k[6:]: v.item() if np.size(v) == 1 else v for k, v in d.items() if k.startswith("param_")}
        check_params(params, where)
        for k, kinds in (("nodes", "iuf"), ("triangles", "iu"), ("node_dofs", "iu")):
            if k in maps and np.asarray(maps[k]).dtype.kind not in kinds:
                raise InputError(f"array 'map_{k}' in {where} must hold {'integers' if kinds == 'iu' else 'numbers'}, "
                                 f"got dtype {np.asarray(maps[k]).dtype}")
        rest, parts = _parts_from_maps(maps, n)     # map_x_shift, map_nodes, ...: the documented file arrays
        if "E" in params and "nu" in params:        # validated by check_params: for post-processing only
            parts["material"] = MaterialPart(float(params["E"]), float(params["nu"]),
                                             str(params.get("plane", "strain")))
        g = parts.get("geometry")
        if g is not None and params.get("element", "P1") != "P1":      # a quadratic mesh (scene key element)
            parts["geometry"] = g = dataclasses.replace(g, element=str(params["element"]))
        if g is not None:       # the defect maps, checked before the interface part is made from them
            check_maps(rest, B.shape[0], g.nodes.shape[1], where, dim=g.dim)
        qp = cls(K=K, F=F, B=B, weights=w, name=path.stem, maps=Maps(rest), params=params, **parts)
        geometry_keys = [k for k in ("nodes", "triangles", "node_dofs") if k in maps]
        if geometry_keys and qp.geometry is None:
            raise InputError(f"{where} holds map_{geometry_keys[0]} but not a consistent mesh: map_nodes (2 or 3, "
                             f"n_nodes), map_triangles and map_node_dofs are needed together")
        legacy = qp.maps.legacy() if isinstance(qp.maps, Maps) else qp.maps
        check_maps(legacy, qp.m, None if qp.geometry is None else qp.geometry.nodes.shape[1], where,
                   dim=2 if qp.geometry is None else qp.geometry.dim)
        qp.check()
        return qp


# ``K_fixed`` and ``local_dofs`` are init-only keywords of the dataclass (a shorthand for ``local``) and,
# once constructed, read-only views of ``local`` (set after the decorator, which would take them for defaults)
def _k_fixed(self: QP) -> sp.csc_matrix:
    """``local.K_fixed``: the delta-free part of K (K itself when the QP has no local structure)."""
    return self.local.K_fixed  # type: ignore[union-attr]


def _local_dofs(self: QP) -> np.ndarray:
    """``local.dofs``: the unknowns on which K - K_fixed and B act."""
    return self.local.dofs  # type: ignore[union-attr]


setattr(QP, "K_fixed", property(_k_fixed))  # noqa: B010 - mypy must not see a second K_fixed
setattr(QP, "local_dofs", property(_local_dofs))  # noqa: B010
