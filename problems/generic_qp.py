"""``qp_file``: any convex QP ``min 1/2 x'Px + q'x  s.t.  Gx >= h`` read from ``.npz`` or ``.mat``.

So every registered solver can be run (and compared, benchmarked, certified by the evaluator) on
matrices from other codes: ``dualfem solve my_problem.npz --solver pdas``.

File layout (array names; ``h`` may be omitted, meaning 0):

* ``.npz`` (``numpy.savez``): ``P``, ``q``, ``G``, ``h`` as dense arrays, or any matrix ``M`` of
  ``P``/``G`` as COO triplets ``M_data``, ``M_row``, ``M_col``, ``M_shape``.
* ``.mat`` (``scipy.io.savemat`` / MATLAB ``save -v7``): ``P``, ``q``, ``G``, ``h``, dense or sparse.
* A file written by ``dualfem export`` (arrays ``K_*``, ``F``, ``B_*``, ...) is read as that QP.

Validation (each failure is an :class:`~dualfem.errors.InputError` naming the array): before
anything is decompressed, the shapes the file's headers declare must fit in the available memory
(:func:`dualfem.core.qpfile.read_arrays`); no complex array (never read as its real part); a matrix
given both as ``M`` and as triplets ``M_*`` is ambiguous; declared COO shapes must agree with q
and fit in memory; n >= 1 (m = 0, no constraint, is allowed); shapes
(``P`` n x n, ``q`` length n, ``G`` m x n, ``h`` length m), NaN/inf, symmetry of P (relative to
``max|P|``, threshold ``symmetry_rtol``; a file holding only one triangle of P, as OSQP does, is
read with ``p_storage = "upper"`` or ``"lower"``), positive diagonal, and, if ``check_definite``,
positive definiteness by a sparse LDL'-type factorization (SuperLU with symmetric ordering and no
pivoting; its pivots are the LDL' pivots, all > 0 iff P is SPD). This costs one factorization of P,
the same as the cheapest solver's setup; turn it off for very large files.

**Bounds that are not constraints.** A row with ``h_j <= -1e20`` or ``h_j = -inf`` can never bind
(qpsolvers and OSQP read 1e20 and beyond as infinite): it is dropped before anything else
(:func:`drop_free_rows`; ``qp.maps["constraint_rows"]`` are the rows kept, and the multiplier of a
dropped row is 0: :func:`original_multipliers`). ``h_j = +inf`` or NaN is refused. A merely loose bound
(h = -1e8) stays a constraint; its shift (below) costs precision (the file's x is ``z + x0`` with
``|x0| ~ 1e8``), and that cost shows up honestly in the certified status (``inaccurate``), never as a
wrong ``solved``: the evaluator certifies the answer in the file's own unknowns against the file's own
``q`` and ``h`` (kept with the shift: ``qp.shift.load = -q``, ``qp.shift.rhs = h``), and reads no scale
from the file.

**Conventions and the h != 0 limitation.** dualfem's QP type is ``min 1/2 x'Kx - F'x s.t.
Bx >= 0`` (a cone through the origin), so ``K = P``, ``F = -q``, ``B = G``. For ``h != 0`` the
problem is shifted: find ``x0`` with ``G x0 = h`` (minimum-norm solution; needs ``h`` in the range
of G, which holds whenever G has full row rank, e.g. gap functions with m <= n) and solve for
``z = x - x0``:

    min 1/2 z'Pz + (q + P x0)'z   s.t.  Gz >= 0.

The multipliers are unchanged (``Pz + q + P x0 = G'mu``, i.e. ``Px + q = G'mu``), the solvers'
``x`` is ``z``; the original unknowns are ``x = z + qp.shift.x`` and the original
objective is ``qp.energy(z) + qp.shift.objective``. If ``G x0 = h`` has no solution (for
example box constraints ``[I; -I] x >= [l; -u]``, m > n) the file is refused with a message
saying so: such feasible sets are not cones after any shift and need an extension of the QP type.
P must be positive definite (every solver's contract); a singular P is refused.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from dualfem.core.errors import InputError, check_positive
from dualfem.core.io import check_input_path
from dualfem.core.parts import ShiftPart
from dualfem.core.problem import Problem
from dualfem.core.qp import QP
from dualfem.core.qpfile import check_dims, coo_from_arrays, declared_arrays, read_arrays
from dualfem.core.registry import register_problem

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
    """A sparse matrix from a dense/sparse array ``name`` or COO triplets ``name_*`` (not both: ambiguous).

    ``rows``/``cols``: the sizes implied by the other arrays (q's length), checked against the
    declared shape before anything of that shape is allocated."""
    keys = [f"{name}_{s}" for s in ("data", "row", "col", "shape")]
    if name in d and any(k in d for k in keys):
        raise InputError(f"{where} holds both the matrix {name!r} and the triplets "
                         f"{', '.join(k for k in keys if k in d)}: ambiguous, keep one")
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
    """(G, h) without the rows that can never bind (``h_j <= -FREE_BOUND`` or ``-inf``), and the indices
    of the rows kept (into the file's rows). NaN or ``+inf`` in h is refused (``G_j x >= +inf`` has no
    solution). A merely loose bound (h = -1e8) is kept: it is a constraint, and whatever precision its
    shift costs shows up in the certified status."""
    if np.any(np.isnan(h)):
        raise InputError(f"array 'h' in {where} contains NaN entries")
    if np.any(h == np.inf):
        raise InputError(f"array 'h' in {where} contains +inf: G_j x >= +inf has no solution (use -inf or "
                         f"h <= -{FREE_BOUND:g} for 'no constraint')")
    keep = np.flatnonzero(h > -FREE_BOUND)
    if keep.size == h.size:
        return G, h, keep
    return G[keep], h[keep], keep


def original_multipliers(qp: QP, mu: np.ndarray) -> np.ndarray:
    """The multipliers of the file's rows (length of the file's h): 0 for a row dropped as "no
    constraint" (:func:`drop_free_rows`)."""
    mu = np.asarray(mu, dtype=float)
    rows = qp.maps.get("constraint_rows") if isinstance(qp.maps, dict) else None
    if rows is None:
        return mu
    out = np.zeros(int(np.asarray(qp.maps["n_file_rows"])))
    out[np.asarray(rows, dtype=np.int64)] = mu
    return out


def shift_for(G: sp.csr_matrix, h: np.ndarray, where: str) -> np.ndarray:
    """The minimum-norm ``x0`` with ``G x0 = h``; InputError if there is none."""
    n = G.shape[1]
    if not np.any(h):
        return np.zeros(n)
    x0 = None
    try:
        y = sla.splu(sp.csc_matrix(G @ G.T), permc_spec="MMD_AT_PLUS_A").solve(h)
        x0 = G.T @ y
    except RuntimeError:  # G G' singular: rank-deficient G
        pass
    if x0 is None or not np.all(np.isfinite(x0)) or \
            np.abs(G @ x0 - h).max() > 1e-9 * max(np.abs(h).max(), 1e-300):
        x0 = sla.lsqr(G, h, atol=1e-15, btol=1e-15, iter_lim=10 * (n + G.shape[0]))[0]
    err = np.abs(G @ x0 - h).max() / max(np.abs(h).max(), 1e-300)
    if not np.isfinite(err) or err > 1e-8:
        raise InputError(
            f"h in {where} is not in the range of G (min |G x0 - h| / |h| = {err:.1e}): dualfem's QP type is "
            f"B x >= 0, and h != 0 is supported by the shift x = z + x0 with G x0 = h, which needs G of full "
            f"row rank or a consistent h; constraints such as box bounds (m = {G.shape[0]} rows > n = {n}) "
            f"are not supported")
    return x0


@register_problem
class QPFile(Problem):
    """A QP ``min 1/2 x'Px + q'x s.t. Gx >= h`` (or a ``dualfem export`` file) from .npz/.mat."""

    name = "qp_file"
    description = "any QP min 1/2 x'Px + q'x s.t. Gx >= h from a .npz/.mat file (dualfem solve FILE.npz)"
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
        if ("K_data" in d or "K" in d) and ("F" in d):
            letters = [k for k in ("P", "q", "G", "h", "P_data", "G_data") if k in d]
            if letters:
                raise InputError(f"{where} holds both an exported QP (K, F, B) and the arrays {', '.join(letters)} "
                                 f"of min 1/2 x'Px + q'x s.t. Gx >= h: ambiguous, keep one")
            qp = QP.load(path)           # a file written by `dualfem export` / QP.save
            qp.name = f"qp_file[{path.stem}]"
            qp.params = {**qp.params, **{k: str(v) for k, v in p.items()}}
            if p["check_definite"]:
                check_definite(qp.K, where)
            return qp
        nq = _length(d, "q")          # the size every declared shape must agree with
        P = _matrix(d, "P", where, rows=nq, cols=nq)
        n = P.shape[0]
        if P.shape != (n, n):
            raise InputError(f"P in {where} must be square, got shape {P.shape}")
        if n == 0:
            raise InputError(f"P in {where} has shape (0, 0): a QP needs at least one unknown (n >= 1)")
        q = _vector(d, "q", where, n, "the size of P")
        G = _matrix(d, "G", where, required=False, cols=n)
        if G is None:
            raise InputError(f"{where} lacks the constraint matrix 'G' (use a G of shape (0, {n}) for no constraints)")
        if G.shape[1] != n:
            raise InputError(f"G in {where} must have {n} columns (the size of P), got shape {G.shape}")
        m = G.shape[0]
        h = _vector(d, "h", where, m, "the number of rows of G", required=False)
        h = np.zeros(m) if h is None else h
        for nm, arr in (("P", P.data), ("q", q), ("G", G.data)):
            if not np.all(np.isfinite(arr)):
                raise InputError(f"array {nm!r} in {where} contains NaN or infinite entries")
        G, h, rows = drop_free_rows(sp.csr_matrix(G), h, where)
        if p["p_storage"] != "full":
            T = sp.triu(P, format="csc") if p["p_storage"] == "upper" else sp.tril(P, format="csc")
            if (P - T).count_nonzero() > 0:
                raise InputError(f"p_storage = {p['p_storage']!r} but P in {where} has entries in the other triangle")
            P = (T + T.T - sp.diags(T.diagonal())).tocsc()
        asym = _absmax(P - P.T)
        scale = max(_absmax(P), 1e-300)
        if asym > p["symmetry_rtol"] * scale:
            hint = ""
            if sp.tril(P, -1).nnz == 0 or sp.triu(P, 1).nnz == 0:
                hint = (" (it holds one triangle only: set p_storage = 'upper' or 'lower', "
                        "e.g. --set p_storage=upper)")
            raise InputError(f"P in {where} must be symmetric: max |P - P'| / max |P| = {asym / scale:.2e} > "
                             f"symmetry_rtol = {p['symmetry_rtol']:g}{hint}")
        P = (0.5 * (P + P.T)).tocsc()
        diag = P.diagonal()
        if np.any(diag <= 0):
            j = int(np.flatnonzero(diag <= 0)[0])
            raise InputError(f"P in {where} is not positive definite: diagonal entry P[{j},{j}] = {diag[j]:g} <= 0")
        if p["check_definite"]:
            check_definite(P, where)
        G = G.tocsr()
        x0 = shift_for(G, h, where)
        F = -(q + P @ x0)
        offset = float(0.5 * x0 @ (P @ x0) + q @ x0)
        # the file's own q and h go with the shift: the evaluator certifies the answer in the file's
        # unknowns against them (F above lost the digits of q below the rounding of P x0)
        qp = QP(K=P, F=F, B=G, name=f"qp_file[{path.stem}]",
                params={k: str(v) for k, v in p.items()},
                maps={"constraint_rows": rows, "n_file_rows": np.array(m)},
                shift=ShiftPart.make(x0, offset, load=-q, rhs=h))
        return qp


def original_x(qp: QP, x: np.ndarray) -> np.ndarray:
    """The unknowns of the file's QP from a solver's ``x`` (undo the h-shift)."""
    return np.asarray(x) if qp.shift is None else np.asarray(x) + qp.shift.x


def original_objective(qp: QP, x: np.ndarray) -> float:
    """``1/2 x'Px + q'x`` of the file's QP at ``original_x(qp, x)``, computed from the file's unknowns
    (not ``qp.energy(x) + shift.objective``, which cancels catastrophically when the shift is large)."""
    from dualfem.core.evaluator import user_frame

    uf = user_frame(qp, np.asarray(x, dtype=float))
    if uf is None:
        return qp.energy(x)
    y, Fu, _ = uf
    return float(0.5 * y @ (qp.K @ y) - Fu @ y)
