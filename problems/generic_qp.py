"""``qp_file``: any convex QP read from ``.npz`` or ``.mat``, in one of two conventions named by its arrays.

So every registered solver can be run (and compared, benchmarked, certified by the evaluator) on
matrices from other codes: ``dualfem solve my_problem.npz --solver pdas``.

**The two conventions** (:data:`dualfem.core.qpfile.CONVENTIONS`; the array names decide):

* **qpsolvers'** (the ecosystem's: qpsolvers, OSQP, Clarabel, ...): ``P, q`` and optionally ``G, h``,
  ``A, b``, ``lb, ub``::

      minimize 1/2 x'Px + q'x   subject to   G x <= h,   A x = b,   lb <= x <= ub

  An omitted ``h`` or ``b`` is 0. A bound that can never bind (``h_j``, ``ub_j`` of +inf or >= 1e20,
  ``lb_j`` of -inf or <= -1e20, as qpsolvers and OSQP read them) is no constraint. The multipliers in
  qpsolvers' signs (``z``, ``y``, ``z_box`` with ``P x + q + G'z + A'y + z_box = 0``):
  :func:`qpsolvers_duals`.
* **dualfem's own**: ``K, F, B`` and optionally ``Bx_min``::

      minimize 1/2 x'Kx - F'x   subject to   B x >= Bx_min   (Bx_min omitted: 0)

  A file written by ``dualfem export`` (arrays ``K_*``, ``F``, ``B_*``, ``weights``, ``map_*``, ...) is
  this convention with ``Bx_min = 0`` and is read by :meth:`dualfem.core.qp.QP.load`, as before.

A file holding names of both conventions (it could be read either way), of neither, or an optional
string array ``convention`` that does not start with the convention its names declare (``qpsolvers``
or ``dualfem``) is refused with a message naming both (:func:`dualfem.core.qpfile.convention`).

File layout: every matrix (``P``, ``G``, ``A``, ``K``, ``B``) as a dense array, in a ``.mat`` file also
as a sparse matrix, as COO triplets ``M_data``, ``M_row``, ``M_col``, ``M_shape`` (0-based), or as CSC
arrays ``M_data``, ``M_indices``, ``M_indptr``, ``M_shape`` (scipy's, as the public test set writes them,
:mod:`dualfem.experiments.testset_files`); ``.mat`` files from ``scipy.io.savemat`` or MATLAB ``save -v7``.

Validation (each failure is an :class:`~dualfem.errors.InputError` naming the array): before
anything is decompressed, the shapes the file's headers declare must fit in the available memory
(:func:`dualfem.core.qpfile.read_arrays`); no complex array (never read as its real part); a matrix
given both as ``M`` and as triplets ``M_*`` is ambiguous; declared COO shapes must agree with q (F)
and fit in memory; n >= 1 (m = 0, no constraint, is allowed); shapes, NaN/inf, a bound no x
satisfies (``h_j = -inf``, ``lb_j = +inf``, ``ub_j = -inf``, ``lb_j > ub_j``, ``Bx_min_j = +inf``), symmetry
of P (relative to ``max|P|``, threshold ``symmetry_rtol``; a file holding only one triangle of P, as
OSQP does, is read with ``p_storage = "upper"`` or ``"lower"``), positive diagonal, and, if
``check_definite``, positive definiteness by a sparse LDL'-type factorization (SuperLU with symmetric
ordering and no pivoting; its pivots are the LDL' pivots, all > 0 iff P is SPD). This costs one
factorization of P, the same as the cheapest solver's setup; turn it off for very large files.

**To dualfem's QP type.** dualfem's QP is ``min 1/2 x'Kx - F'x s.t. Cx >= 0`` (a cone through the
origin). Both conventions are first written as rows ``C x >= c``: qpsolvers' as
``C = [-G; A; -A; I; -I]``, ``c = [-h; b; -b; lb; -ub]`` (``maps["row_blocks"]``: the five block
sizes, 0 for an absent array; an equality is two opposite rows, so its multipliers are not unique and
the certificate may rate an exact answer only ``inaccurate``), dualfem's as ``C = B``, ``c = Bx_min``.
Rows that can never bind are dropped (:func:`drop_free_rows`; ``maps["constraint_rows"]`` the rows
kept, :func:`original_multipliers`). For ``c != 0`` the problem is shifted: find ``x0`` with
``C x0 = c`` (minimum-norm; needs ``c`` in the range of C, which holds whenever the kept rows are
linearly independent, e.g. gap functions with m <= n) and solve for ``z = x - x0``::

    min 1/2 z'Pz + (q + P x0)'z   s.t.  Cz >= 0.

The multipliers are unchanged, the solvers' ``x`` is ``z``; the original unknowns are
``x = z + qp.shift.x`` (:func:`original_x`) and the original objective :func:`original_objective`.
The evaluator certifies the answer in the file's own unknowns against the file's own ``q`` and
``c`` (kept with the shift: ``qp.shift.load = -q``, ``qp.shift.rhs = c``) and reads no scale from the
file, so what a large shift (h = 1e8) costs in precision shows up as ``inaccurate``, never as a wrong
``solved``. If ``C x0 = c`` has no solution (box constraints: lb and ub on the same unknowns, m > n
rows) the file is refused with a message saying so. P must be positive definite (every solver's
contract); a singular P is refused.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from dualfem.core.io import check_input_path
from dualfem.core.qpfile import check_dims, convention, coo_from_arrays, csc_from_arrays, declared_arrays, read_arrays
from dualfem.errors import InputError, check_positive
from dualfem.problem import Problem
from dualfem.qp import QP, ShiftPart
from dualfem.registry import register_problem

STORAGE = ("full", "upper", "lower")


def _read(path: Path) -> dict:
    check_input_path(path, "QP file")      # a FIFO or a device: refused before anything opens it
    if path.suffix not in (".npz", ".mat"):
        raise InputError(f"parameter 'path' must name a .npz or .mat file, got {str(path)!r}")
    try:
        return read_arrays(path, f"QP file {str(path)!r}")   # declared sizes checked before decompressing
    except InputError:
        raise
    except NotImplementedError as exc:  # scipy.io cannot read MATLAB v7.3 (HDF5) files
        raise InputError(f"cannot read QP file {str(path)!r}: {exc}; save it from MATLAB with "
                         f"save(..., '-v7') instead") from None
    except Exception as exc:  # corrupt or not a numpy/MATLAB file
        raise InputError(f"cannot read QP file {str(path)!r}: {type(exc).__name__}: {exc}") from None


def _matrix(d: dict, name: str, where: str, required: bool = True, rows: int | None = None,
            cols: int | None = None):
    """A sparse matrix from a dense/sparse array ``name``, COO triplets or CSC arrays ``name_*`` (not both:
    ambiguous).

    ``rows``/``cols``: the sizes implied by the other arrays (q's length), checked against the
    declared shape before anything of that shape is allocated."""
    keys = [f"{name}_{s}" for s in ("data", "row", "col", "shape")]
    if name in d and any(k in d for k in keys + [f"{name}_indices", f"{name}_indptr"]):
        raise InputError(f"{where} holds both the matrix {name!r} and the triplets "
                         f"{', '.join(k for k in d if k.startswith(name + '_'))}: ambiguous, keep one")
    if name in d:
        a = d[name]
        if sp.issparse(a):
            if a.dtype.kind not in "biuf":
                raise InputError(f"matrix {name!r} in {where} must be real numbers, got dtype {a.dtype}")
            check_dims(name, a.shape, where)        # a MATLAB sparse matrix's row count is only declared
            return sp.csc_matrix(a, dtype=float)
        a = np.asarray(a)
        if a.dtype.kind not in "biuf":
            raise InputError(f"array {name!r} in {where} must be numeric, got dtype {a.dtype}")
        if a.ndim != 2:
            raise InputError(f"array {name!r} in {where} must be 2-D, got shape {a.shape}")
        return sp.csc_matrix(a.astype(float))
    if all(k in d for k in (f"{name}_data", f"{name}_indices", f"{name}_indptr", f"{name}_shape")):
        return csc_from_arrays(d, name, where, rows=rows, cols=cols)
    if all(k in d for k in keys):
        return sp.csc_matrix(coo_from_arrays(d, name, where, rows=rows, cols=cols, against="the length of q"))
    if any(k in d for k in keys):
        raise InputError(f"{where} holds only part of the triplets of {name!r}: it needs all of {', '.join(keys)}")
    if required:
        raise InputError(f"{where} lacks the matrix {name!r} (a 2-D array {name!r} or the COO triplets "
                         f"{', '.join(keys)})")
    return None


def _length(d: dict, name: str) -> int | None:
    """The length of the vector ``name`` if the file has one (an array of any shape: its size)."""
    return int(np.size(d[name])) if name in d and not sp.issparse(d[name]) else None


def _vector(d: dict, name: str, where: str, n: int, what: str, required: bool = True):
    if name not in d:
        if required:
            raise InputError(f"{where} lacks the vector {name!r}")
        return None
    a = d[name]
    a = np.asarray(a.toarray() if sp.issparse(a) else a)
    if a.dtype.kind not in "biuf":
        raise InputError(f"array {name!r} in {where} must be numeric, got dtype {a.dtype}")
    if a.ndim > 2 or (a.ndim == 2 and min(a.shape) != 1):
        raise InputError(f"array {name!r} in {where} must be a vector, got shape {a.shape}")
    a = a.astype(float).ravel()
    if a.size != n:
        raise InputError(f"array {name!r} in {where} must have length {n} ({what}), got {a.size}")
    return a


def _absmax(M: sp.spmatrix) -> float:
    M = sp.csr_matrix(M)
    return float(np.abs(M.data).max()) if M.nnz else 0.0


def check_definite(P: sp.spmatrix, where: str) -> None:
    """Raise InputError unless the symmetric matrix P is positive definite (one sparse factorization)."""
    n = P.shape[0]
    if n == 0:
        return
    try:
        lu = sla.splu(sp.csc_matrix(P), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                      options={"SymmetricMode": True})
    except RuntimeError as exc:  # "Factor is exactly singular"
        raise InputError(f"P in {where} is singular ({exc}); dualfem needs a positive definite P") from None
    d = lu.U.diagonal()
    # with symmetric ordering and no pivoting, U's diagonal is D of P = L D L'
    if not (np.all(lu.perm_r == lu.perm_c)):
        raise InputError(f"P in {where}: the factorization pivoted, so P is not positive definite")
    scale = max(np.abs(P.diagonal()).max(initial=0.0), 1e-300)
    bad = np.flatnonzero(~(d > 1e-14 * scale))
    if bad.size:
        raise InputError(f"P in {where} is not positive definite: pivot {d[bad[0]]:.3e} (of max diagonal "
                         f"{scale:.3e}) in its LDL' factorization; dualfem needs a positive definite P")


#: a row with ``h <= -FREE_BOUND`` (or ``-inf``) is "no constraint", as qpsolvers and OSQP read bounds
#: beyond 1e20 as infinite: it is dropped, and its multiplier is 0 in everything reported
FREE_BOUND = 1e20


def drop_free_rows(G: sp.csr_matrix, h: np.ndarray, where: str) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """Rows ``G x >= h`` (dualfem's form, built by :func:`_qpsolvers_rows` / :func:`_own_rows`) without
    those that can never bind (``h_j <= -FREE_BOUND`` or ``-inf``), and the indices of the rows kept
    (into the stacked rows of the file). The readers refuse NaN and a bound no x satisfies first, in the
    file's own convention. A merely loose bound (1e8) is kept: it is a constraint, and whatever
    precision its shift costs shows up in the certified status."""
    if np.any(np.isnan(h)) or np.any(h == np.inf):
        raise InputError(f"the constraints of {where} hold NaN or a bound no x satisfies")
    keep = np.flatnonzero(h > -FREE_BOUND)
    if keep.size == h.size:
        return G, h, keep
    return G[keep], h[keep], keep


def original_multipliers(qp: QP, mu: np.ndarray) -> np.ndarray:
    """The multipliers (>= 0) of every stacked row ``C x >= c`` of the file (``row_blocks``: for qpsolvers'
    names ``[-G; A; -A; I; -I]``, for dualfem's ``B``): 0 for a row dropped as "no constraint"
    (:func:`drop_free_rows`)."""
    mu = np.asarray(mu, dtype=float)
    rows = qp.maps.get("constraint_rows") if isinstance(qp.maps, dict) else None
    if rows is None:
        return mu
    out = np.zeros(int(np.asarray(qp.maps["n_file_rows"])))
    out[np.asarray(rows, dtype=np.int64)] = mu
    return out


def qpsolvers_duals(qp: QP, mu: np.ndarray) -> dict[str, np.ndarray | None]:
    """The multipliers of a qpsolvers-convention file in qpsolvers' own signs: ``z`` (>= 0, of
    ``G x <= h``), ``y`` (of ``A x = b``) and ``z_box`` (of ``lb <= x <= ub``: < 0 at an active lower
    bound, > 0 at an active upper one), so that ``P x + q + G'z + A'y + z_box = 0``; None for an
    array the file does not have."""
    full = original_multipliers(qp, mu)
    sizes = np.asarray(qp.maps["row_blocks"], dtype=np.int64)
    g, ap, am, lo, up = np.split(full, np.cumsum(sizes)[:-1])
    present = sizes > 0
    n = qp.n
    box = None
    if present[3] or present[4]:
        box = (up if present[4] else np.zeros(n)) - (lo if present[3] else np.zeros(n))
    return {"z": g if present[0] else None, "y": (am - ap) if present[1] else None, "z_box": box}


def shift_for(C: sp.csr_matrix, c: np.ndarray, where: str) -> np.ndarray:
    """The minimum-norm ``x0`` with ``C x0 = c`` (the rows ``C x >= c`` of a file); InputError if there is none."""
    n = C.shape[1]
    if not np.any(c):
        return np.zeros(n)
    x0 = None
    try:
        y = sla.splu(sp.csc_matrix(C @ C.T), permc_spec="MMD_AT_PLUS_A").solve(c)
        x0 = C.T @ y
    except RuntimeError:  # C C' singular: rank-deficient C
        pass
    if x0 is None or not np.all(np.isfinite(x0)) or \
            np.abs(C @ x0 - c).max() > 1e-9 * max(np.abs(c).max(), 1e-300):
        x0 = sla.lsqr(C, c, atol=1e-15, btol=1e-15, iter_lim=10 * (n + C.shape[0]))[0]
    err = np.abs(C @ x0 - c).max() / max(np.abs(c).max(), 1e-300)
    if not np.isfinite(err) or err > 1e-8:
        raise InputError(
            f"the constraints of {where} have no point x0 on all their bounds (min |C x0 - c| / |c| = {err:.1e}, "
            f"C x >= c: the file's rows in dualfem's form): dualfem's QP type is B x >= 0, and nonzero bounds are "
            f"supported by the shift x = z + x0 with C x0 = c, which needs C of full row rank or consistent bounds; "
            f"box constraints (lb and ub on the same unknowns, or {C.shape[0]} rows > n = {n}) are not in the range "
            f"of such a shift and are not supported")
    return x0


@register_problem
class QPFile(Problem):
    """A QP from .npz/.mat: qpsolvers' ``min 1/2 x'Px + q'x s.t. Gx <= h, Ax = b, lb <= x <= ub`` or
    dualfem's ``min 1/2 x'Kx - F'x s.t. Bx >= Bx_min`` (a ``dualfem export`` file); see the module docstring."""

    name = "qp_file"
    description = ("any QP from a .npz/.mat file: qpsolvers' P, q, G, h[, A, b, lb, ub] (G x <= h) or dualfem's "
                   "K, F, B[, Bx_min] (B x >= Bx_min) (dualfem solve FILE.npz)")
    defaults = {
        "path": "",
        "p_storage": "full",
        "symmetry_rtol": 1e-10,
        "check_definite": True,
    }

    def validate(self) -> None:
        p = self.params
        if not isinstance(p["path"], (str, Path)) or not str(p["path"]).strip():
            raise InputError("parameter 'path' of problem 'qp_file' must name a .npz or .mat file")
        p["path"] = str(p["path"]).strip()
        if Path(p["path"]).suffix not in (".npz", ".mat"):
            raise InputError(f"parameter 'path' must name a .npz or .mat file, got {p['path']!r}")
        if p["p_storage"] not in STORAGE:
            raise InputError(f"p_storage must be one of {', '.join(STORAGE)}, got {p['p_storage']!r}")
        p["symmetry_rtol"] = check_positive("symmetry_rtol", p["symmetry_rtol"])

    def size_estimate(self) -> tuple[int, str] | None:
        """Unknowns declared by the file's headers (q or F: nothing decompressed), for the memory guard."""
        path = Path(self.params["path"])
        try:
            decl = declared_arrays(path)
        except Exception:  # noqa: BLE001 - unreadable: build() says why, in one line
            return None
        for name in ("q", "F"):
            if name in decl and decl[name][1] != "sparse":
                n = int(np.prod(decl[name][0]))
                return (n, f"QP file {path.name!r} (n = {n})") if n >= 1 else None
        return None

    def build(self) -> QP:
        p = self.params
        path = Path(p["path"])
        where = f"QP file {str(path)!r}"
        d = _read(path)
        conv = convention(d, where)         # refuses a file whose names fit both conventions, or neither
        if conv == "dualfem" and "Bx_min" not in d and not any(_dense(d, k) for k in ("K", "B")):
            qp = QP.load(path)           # a file written by `dualfem export` / QP.save: B x >= 0
            qp.name = f"qp_file[{path.stem}]"
            qp.params = {**qp.params, **{k: str(v) for k, v in p.items()}, "convention": conv}
            if p["check_definite"]:
                check_definite(qp.K, where)
            return qp
        P, q, C, c, blocks = (_qpsolvers_rows if conv == "qpsolvers" else _own_rows)(d, where)
        P = self._checked_P(P, where, "P" if conv == "qpsolvers" else "K")
        C, c, rows = drop_free_rows(C.tocsr(), c, where)
        x0 = shift_for(C, c, where)
        F = -(q + P @ x0)
        offset = float(0.5 * x0 @ (P @ x0) + q @ x0)
        # the file's own q and rows go with the shift: the evaluator certifies the answer in the file's
        # unknowns against them (F above lost the digits of q below the rounding of P x0)
        return QP(K=P, F=F, B=C, name=f"qp_file[{path.stem}]",
                  params={**{k: str(v) for k, v in p.items()}, "convention": conv},
                  maps={"constraint_rows": rows, "n_file_rows": np.array(blocks.sum()),
                        "row_blocks": blocks},
                  shift=ShiftPart.make(x0, offset, load=-q, rhs=c))

    def _checked_P(self, P: sp.csc_matrix, where: str, name: str) -> sp.csc_matrix:
        """The objective's matrix (``name``: P or K) read with ``p_storage``, symmetric to ``symmetry_rtol``,
        positive diagonal, and (with ``check_definite``) positive definite; returned symmetrised."""
        p = self.params
        if p["p_storage"] != "full":
            T = sp.triu(P, format="csc") if p["p_storage"] == "upper" else sp.tril(P, format="csc")
            if (P - T).count_nonzero() > 0:
                raise InputError(f"p_storage = {p['p_storage']!r} but {name} in {where} has entries in the other "
                                 f"triangle")
            P = (T + T.T - sp.diags(T.diagonal())).tocsc()
        asym = _absmax(P - P.T)
        scale = max(_absmax(P), 1e-300)
        if asym > p["symmetry_rtol"] * scale:
            hint = ""
            if sp.tril(P, -1).nnz == 0 or sp.triu(P, 1).nnz == 0:
                hint = (" (it holds one triangle only: set p_storage = 'upper' or 'lower', "
                        "e.g. --set p_storage=upper)")
            raise InputError(f"{name} in {where} must be symmetric: max |P - P'| / max |P| = {asym / scale:.2e} > "
                             f"symmetry_rtol = {p['symmetry_rtol']:g}{hint}")
        P = (0.5 * (P + P.T)).tocsc()
        diag = P.diagonal()
        if np.any(diag <= 0):
            j = int(np.flatnonzero(diag <= 0)[0])
            raise InputError(f"{name} in {where} is not positive definite: diagonal entry {name}[{j},{j}] = "
                             f"{diag[j]:g} <= 0")
        if p["check_definite"]:
            check_definite(P, where)
        return P


def _dense(d: dict, name: str) -> bool:
    """True when the file gives matrix ``name`` as a plain (dense) array."""
    return name in d and not sp.issparse(d[name])


def _objective(d: dict, where: str, P: str, q: str) -> tuple[sp.csc_matrix, np.ndarray]:
    nq = _length(d, q)          # the size every declared shape must agree with
    M = _matrix(d, P, where, rows=nq, cols=nq)
    n = M.shape[0]
    if M.shape != (n, n):
        raise InputError(f"{P} in {where} must be square, got shape {M.shape}")
    if n == 0:
        raise InputError(f"{P} in {where} has shape (0, 0): a QP needs at least one unknown (n >= 1)")
    v = _vector(d, q, where, n, f"the size of {P}")
    for nm, arr in ((P, M.data), (q, v)):
        if not np.all(np.isfinite(arr)):
            raise InputError(f"array {nm!r} in {where} contains NaN or infinite entries")
    return M, v


def _rows(d: dict, M: str, v: str, where: str, n: int):
    """(matrix, right-hand side) of one block of constraints, or (None, None) when the file has no ``M``."""
    A = _matrix(d, M, where, required=False, cols=n)
    if A is None:
        if v in d:
            raise InputError(f"{where} holds {v!r} but not the matrix {M!r}: give both or neither")
        return None, None
    if A.shape[1] != n:
        raise InputError(f"{M} in {where} must have {n} columns (the size of the objective's matrix), got shape "
                         f"{A.shape}")
    if not np.all(np.isfinite(A.data)):
        raise InputError(f"array {M!r} in {where} contains NaN or infinite entries")
    b = _vector(d, v, where, A.shape[0], f"the number of rows of {M}", required=False)
    b = np.zeros(A.shape[0]) if b is None else b
    if np.any(np.isnan(b)):
        raise InputError(f"array {v!r} in {where} contains NaN entries")
    return sp.csr_matrix(A), b


def _qpsolvers_rows(d: dict, where: str):
    """P, q and the constraints of qpsolvers' ``G x <= h, A x = b, lb <= x <= ub`` as rows ``C x >= c``:
    ``C = [-G; A; -A; I; -I]``, ``c = [-h; b; -b; lb; -ub]`` (blocks of absent arrays left out; their sizes
    in ``row_blocks``). A bound of +-inf or beyond 1e20 in magnitude on the free side is "no constraint"."""
    P, q = _objective(d, where, "P", "q")
    n = P.shape[0]
    G, h = _rows(d, "G", "h", where, n)
    A, b = _rows(d, "A", "b", where, n)
    if h is not None and np.any(h == -np.inf):
        raise InputError(f"array 'h' in {where} contains -inf: G_j x <= -inf has no solution (qpsolvers' "
                         f"convention G x <= h: use +inf or h >= {FREE_BOUND:g} for 'no constraint')")
    if b is not None and not np.all(np.isfinite(b)):
        raise InputError(f"array 'b' in {where} must be finite (A x = b)")
    lb = _vector(d, "lb", where, n, "the size of P", required=False)
    ub = _vector(d, "ub", where, n, "the size of P", required=False)
    for nm, v, bad in (("lb", lb, np.inf), ("ub", ub, -np.inf)):
        if v is not None and (np.any(np.isnan(v)) or np.any(v == bad)):
            raise InputError(f"array {nm!r} in {where} contains NaN or {bad:+g}: no x satisfies it")
    if lb is not None and ub is not None and np.any(lb > ub):
        j = int(np.flatnonzero(lb > ub)[0])
        raise InputError(f"lb[{j}] = {lb[j]:g} > ub[{j}] = {ub[j]:g} in {where}: no x satisfies lb <= x <= ub")
    eye = sp.identity(n, format="csr")
    parts = [(-G, -h) if G is not None else None, (A, b) if A is not None else None,
             (-A, -b) if A is not None else None, (eye, lb) if lb is not None else None,
             (-eye, -ub) if ub is not None else None]
    return P, q, *_stack(parts, n)


def _own_rows(d: dict, where: str):
    """K, -F and dualfem's own ``B x >= Bx_min`` (Bx_min omitted: 0) as rows ``C x >= c``."""
    K, F = _objective(d, where, "K", "F")
    B, c = _rows(d, "B", "Bx_min", where, K.shape[0])
    if B is None:
        raise InputError(f"{where} lacks the constraint matrix 'B' (use a B of shape (0, {K.shape[0]}) for no "
                         f"constraints)")
    if np.any(c == np.inf):
        raise InputError(f"array 'Bx_min' in {where} contains +inf: B_j x >= +inf has no solution (use -inf or "
                         f"Bx_min <= -{FREE_BOUND:g} for 'no constraint')")
    return K, -F, *_stack([(B, c)], K.shape[0])


def _stack(parts, n: int):
    """(C, c, row_blocks) of the blocks given (None: a block the file does not have, 0 rows)."""
    mats = [m for m in parts if m is not None]
    C = sp.vstack([m for m, _ in mats], format="csr") if mats else sp.csr_matrix((0, n))
    c = np.concatenate([v for _, v in mats]) if mats else np.zeros(0)
    return C, c, np.array([0 if m is None else m[0].shape[0] for m in parts], dtype=np.int64)


def original_x(qp: QP, x: np.ndarray) -> np.ndarray:
    """The unknowns of the file's QP from a solver's ``x`` (undo the h-shift)."""
    return np.asarray(x) if qp.shift is None else np.asarray(x) + qp.shift.x


def original_objective(qp: QP, x: np.ndarray) -> float:
    """``1/2 x'Px + q'x`` of the file's QP at ``original_x(qp, x)``, computed from the file's unknowns
    (not ``qp.energy(x) + shift.objective``, which cancels catastrophically when the shift is large)."""
    from dualfem.evaluator import user_frame

    uf = user_frame(qp, np.asarray(x, dtype=float))
    if uf is None:
        return qp.energy(x)
    y, Fu, _ = uf
    return float(0.5 * y @ (qp.K @ y) - Fu @ y)
