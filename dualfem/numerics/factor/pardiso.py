"""MKL PARDISO through the ``mkl_rt`` pypardiso installs (mtype 2: real SPD, METIS ordering).

:func:`_lib` loads MKL where pypardiso would find it (pypardiso's own, slow search is the
fallback); pypardiso's ``solve``/``factorize`` cannot pass a Schur set or keep the analysis apart
from the numeric phase, so this module calls the library function with its own buffers: the
upper triangle of A in zero-based CSR (``iparm[34] = 1``), analysis = phase 11 (it reports the
factor's size and the peak memory, ``iparm[14..17]``), numeric
factorization = phase 22, solve = phase 33 (iterative refinement as PARDISO decides).
The halves of a solve split at the Schur set (:meth:`Factorization.forward` / ``backward``) are
phases 331 and 333: with the Schur unknowns I eliminated last and A = L L', phase 331 returns
y = L^-1 b whose R part gives ``q = |y_R|^2 = b_R' A_RR^-1 b_R`` and whose I part is the reduced
right-hand side ``g = b_I - A_IR A_RR^-1 b_R`` (PARDISO leaves the Schur block to the caller);
phase 333 on y with y_I replaced by x_I returns x_R = A_RR^-1 (b_R - A_RI x_I) and x_I unchanged.
Each is half of phase 33 in time (docs/measurements.md); checked against dense solves in
tests/test_factor.py.

Schur complement: with ``iparm[35] = 2`` and the local unknowns marked 1 in ``perm`` (set before
phase 11), phase 22 writes the dense Schur block (unknowns in increasing index order) into the
solution buffer; in this mode phase 33 still solves with the whole matrix (checked against dense
solves in tests/test_factor.py). Mode 1 needs the forward/backward phases 331/333 around a dense
Schur solve; mode 2 is as fast (docs/measurements.md). With a Schur set, the classic factorization
(``iparm[23] = 0``) makes phase 33 run on one thread; the two-level one (``iparm[23] = 1``) keeps it
parallel, so it is used always.
"""
from __future__ import annotations

import ctypes

import numpy as np
import scipy.sparse as sp

from .base import Backend, Factorization, Forward, OrderHint

_LIB = None
#: whether this process has called PARDISO (its OpenMP threads then exist: a forked child would hang in
#: its first call; read by dualfem.experiments.watchdog.fork_is_unsafe)
STARTED = False
_ERRORS = {-1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
           -4: "zero pivot (matrix not positive definite?)", -5: "unclassified internal error",
           -6: "reordering failed", -7: "diagonal matrix is singular", -8: "32-bit integer overflow",
           -9: "not enough memory for out-of-core", -10: "error opening out-of-core files",
           -11: "read/write error with out-of-core files", -12: "wrong pardiso_64 call",
           -13: "interrupted by the callback"}


def _mkl_rt_candidates() -> list[str]:
    """Where an installed MKL (the ``mkl`` wheel pypardiso depends on) keeps ``mkl_rt``: the file named
    by ``PYPARDISO_MKL_RT``, else the library directories of this environment (no recursive search)."""
    import glob
    import os
    import sys

    given = os.environ.get("PYPARDISO_MKL_RT")
    if given:
        return [given]
    found: list[str] = []
    for base in dict.fromkeys((sys.prefix, sys.base_prefix)):
        for pattern in ("lib/libmkl_rt.so*", "lib/libmkl_rt*.dylib", "Library/bin/mkl_rt*.dll"):
            found += sorted(glob.glob(os.path.join(base, pattern)), key=len)
    return found


def _load_pardiso():
    """MKL's ``pardiso`` with pypardiso's argument types. pypardiso's own search (import + one solver object)
    globs the whole environment recursively, twice (slow: docs/measurements.md): the usual places are tried
    first, pypardiso's search only when they hold no loadable ``mkl_rt``. pypardiso must be installed either
    way (it is what ``dualfem[pardiso]`` installs)."""
    import ctypes
    import importlib.util

    if importlib.util.find_spec("pypardiso") is None:
        raise ImportError("No module named 'pypardiso'", name="pypardiso")
    fn = None
    for path in _mkl_rt_candidates():
        try:
            fn = ctypes.CDLL(path).pardiso
            break
        except (OSError, AttributeError):
            continue
    if fn is None:
        import pypardiso

        return pypardiso.PyPardisoSolver()._mkl_pardiso
    P, i32 = ctypes.POINTER, ctypes.c_int32
    fn.argtypes = [P(ctypes.c_int64 if ctypes.sizeof(ctypes.c_void_p) == 8 else i32), P(i32), P(i32), P(i32),
                   P(i32), P(i32), P(None), P(i32), P(i32), P(i32), P(i32), P(i32), P(i32), P(None), P(None),
                   P(i32)]
    fn.restype = None
    return fn


def _lib():
    """MKL's pardiso function (raises ImportError if pypardiso or MKL is unavailable)."""
    global _LIB
    if _LIB is None:
        _LIB = _load_pardiso()
    return _LIB


class PardisoFactorization(Factorization):
    backend = "pardiso"

    def __init__(self, local=None, order: OrderHint = None):
        super().__init__(local, order)          # PARDISO orders with METIS itself: the hint is unused
        self._pt = np.zeros(64, np.int64)
        self._alive = False
        #: MKL's maxfct / mnum: how many numeric factors of the analyzed pattern are kept, and which one the
        #: next factorization writes and the solves use (1 and 1; several: dualfem.numerics.newton_matrix)
        self.maxfct = self.mnum = 1

    def _call(self, phase: int, b: np.ndarray, x: np.ndarray, nrhs: int = 1) -> None:
        global STARTED
        STARTED = True
        P = ctypes.POINTER
        i32 = ctypes.c_int32
        err = i32(0)
        _lib()(self._pt.ctypes.data_as(P(ctypes.c_int64)), ctypes.byref(i32(self.maxfct)),
               ctypes.byref(i32(self.mnum)), ctypes.byref(i32(2)), ctypes.byref(i32(phase)), ctypes.byref(i32(self.n)),
               self._a.ctypes.data_as(P(ctypes.c_double)), self._ia.ctypes.data_as(P(i32)),
               self._ja.ctypes.data_as(P(i32)), self._perm.ctypes.data_as(P(i32)), ctypes.byref(i32(nrhs)),
               self._iparm.ctypes.data_as(P(i32)), ctypes.byref(i32(0)), b.ctypes.data_as(P(ctypes.c_double)),
               x.ctypes.data_as(P(ctypes.c_double)), ctypes.byref(err))
        if err.value != 0:
            raise RuntimeError(f"PARDISO phase {phase} failed with error {err.value}: "
                               f"{_ERRORS.get(err.value, 'unknown error')}")

    def _set_values(self, A: sp.csr_matrix) -> None:
        """The upper triangle of A (canonical CSR, as :meth:`analyze` passes it) in PARDISO's arrays; the mask
        of its entries is kept for :meth:`_factorize` (same pattern). One mask over A's entries instead of
        scipy's ``triu`` (through COO and back, and again at every factorization; docs/measurements.md)."""
        rows = np.repeat(np.arange(A.shape[0], dtype=A.indices.dtype), np.diff(A.indptr))
        keep = A.indices >= rows
        del rows
        nnz = int(np.count_nonzero(keep))
        if nnz >= 2**31:
            raise ValueError("PARDISO (32-bit indices): too many nonzeros")
        self._upper = keep
        self._a = np.ascontiguousarray(A.data[keep], float)
        self._ia = np.concatenate([[0], np.cumsum(keep)])[A.indptr].astype(np.int32)
        self._ja = A.indices[keep].astype(np.int32)
        if np.any(np.diff(self._ia) == 0):
            raise ValueError("PARDISO: the matrix has an empty row in its upper triangle (not SPD)")

    def _analyze(self, A: sp.csr_matrix) -> None:
        _lib()
        self.free()
        self._set_values(A)
        ip = np.zeros(64, np.int32)
        ip[0] = 1          # own values below
        ip[1] = 2          # METIS nested dissection
        ip[9] = 8          # pivot perturbation 1e-8 (unused for SPD)
        ip[17] = -1        # report the factor's nonzeros
        ip[23] = 1         # two-level parallel factorization: with a Schur set the classic one runs the
        #                    solve phase on one thread (docs/measurements.md)
        ip[34] = 1         # zero-based indices
        # Schur by PARDISO only when something is eliminated; onto all unknowns S = A (no
        # Schur mode: an empty eliminated block is an edge case of MKL best not entered)
        self._all_local = self.local.size == self.n
        ip[35] = 2 if 0 < self.local.size < self.n else 0
        self._iparm = ip
        self._perm = np.zeros(self.n, np.int32)
        self._perm[self.local] = 1
        self._alive = True
        dummy = np.zeros(self.n)
        self._call(11, dummy, dummy.copy())
        kb = 1024
        self.info.update({"factor_nnz": int(ip[17]), "analysis_peak_bytes": int(ip[14]) * kb,
                          "permanent_bytes": int(ip[15]) * kb, "factor_bytes": int(ip[16]) * kb,
                          # MKL: total peak = max(iparm[14], iparm[15] + iparm[16])
                          "peak_bytes": int(max(ip[14], ip[15] + ip[16])) * kb,
                          "ordering": "METIS"})

    def _factorize(self, A: sp.csr_matrix) -> None:
        self._a = np.ascontiguousarray(A.data[self._upper], float)     # the pattern analyzed (checked by factorize)
        ns = self.local.size
        if self._all_local:
            self._call(22, np.zeros(self.n), np.zeros(self.n))
            self._schur_buf = A[self.local][:, self.local].toarray()
            return
        x = np.zeros(max(ns * ns, self.n))
        self._call(22, np.zeros(max(ns * ns, self.n)), x)
        if ns:
            S = x[: ns * ns].reshape(ns, ns)                     # rows/cols: local in increasing order
            rank = np.argsort(np.argsort(self.local))            # position of local[i] in sorted order
            S = S[np.ix_(rank, rank)]
            self._schur_buf = 0.5 * (S + S.T)

    def _solve(self, b: np.ndarray) -> np.ndarray:
        bf = np.asfortranarray(b, float)
        x = np.zeros_like(bf)
        self._call(33, bf, x, 1 if b.ndim == 1 else b.shape[1])
        return np.ascontiguousarray(x)

    def _own_schur(self) -> np.ndarray:
        return self._schur_buf

    def _split(self) -> bool:
        """True when the factorization is split at the Schur set (phases 331/333 apply)."""
        return int(self._iparm[35]) != 0

    def _forward(self, b: np.ndarray) -> Forward:
        if not self._split():
            return super()._forward(b)
        y = np.zeros(self.n)
        self._call(331, np.array(b, float), y)
        g = y[self.local]
        y[self.local] = 0.0                      # the state does not depend on b_I (and q is |y_R|^2)
        return Forward(float(y @ y), g, y)

    def _backward(self, fwd: Forward, x_local: np.ndarray) -> np.ndarray:
        if not self._split():
            return super()._backward(fwd, x_local)
        z = np.array(fwd.state, float)
        z[self.local] = x_local
        x = np.zeros(self.n)
        self._call(333, z, x)
        x[self.local] = x_local                  # PARDISO leaves it unchanged; made exact regardless
        return x

    def free(self) -> None:
        if self._alive:
            dummy = np.zeros(max(self.n, 1))
            try:
                self._call(-1, dummy, dummy.copy())
            finally:
                self._alive = False
                self._pt[:] = 0
        super().free()

    def __del__(self):
        try:
            self.free()
        except Exception:  # noqa: BLE001 - interpreter shutdown: nothing left to release
            pass


class PardisoSlots(PardisoFactorization):
    """PARDISO keeping ``maxfct`` numeric factors of one analyzed pattern (MKL's ``maxfct`` / ``mnum``:
    "several factorizations with the same nonzero structure at the same time"): ``slot(k)`` selects the
    factor that the next ``factorize`` writes and ``solve`` uses. One analysis (phase 11) serves all.

    The parent passes its ``maxfct`` and ``mnum`` to MKL; everything else is the parent's."""

    def __init__(self, maxfct: int):
        super().__init__()
        self.maxfct, self.mnum = int(maxfct), 1
        self._values: dict[int, np.ndarray] = {}

    def slot(self, k: int) -> None:
        """Use factor k (0 <= k < maxfct) from now on (its matrix values too, for PARDISO's refinement)."""
        self.mnum = int(k) + 1
        if k in self._values:
            self._a = self._values[k]

    def _factorize(self, A: sp.csr_matrix) -> None:
        super()._factorize(A)
        self._values[self.mnum - 1] = self._a

    def free(self) -> None:
        self._values.clear()
        super().free()


class PardisoBackend(Backend):
    name = "pardiso"
    install_hint = "pip install 'dualfem[pardiso]'  (pypardiso, MKL)"

    @classmethod
    def available(cls) -> bool:
        try:
            _lib()
        except (ImportError, OSError):
            return False
        return True

    def make(self, local: np.ndarray | None = None, order: OrderHint = None) -> Factorization:
        return PardisoFactorization(local, order)

    def multi_factor(self, keep: int) -> Factorization:
        """MKL's ``maxfct`` factors of one analyzed pattern (:class:`PardisoSlots`)."""
        return PardisoSlots(keep)
