"""The factorization interface: one symmetric positive definite sparse matrix, three phases.

A :class:`Backend` makes :class:`Factorization` objects. Their phases are separate so that the
expensive, pattern-only part is reused:

* ``analyze(A)``: fill-reducing ordering and symbolic factorization. Depends on the sparsity
  pattern of ``A`` and on the Schur set ``local`` only, never on the values.
* ``factorize(A)``: numeric factorization (call again with new values on the same pattern).
* ``solve(b)``: ``A^-1 b`` for a 1-D ``b`` (n,) or a 2-D ``b`` (n, k).
* ``schur(local)``: the dense Schur complement ``A_II - A_IR A_RR^-1 A_RI`` onto the indices
  ``local`` (rows and columns in the order given). Fast when ``local`` is the set declared at
  analysis (the backend orders it last / lets the library compute it); otherwise it is computed
  from |I| solves (``S = ((A^-1)_II)^-1``, exact for SPD ``A``).
* ``forward(b)`` / ``backward(fwd, x_local)``: a solve split at the Schur set I = ``local``
  (R = the rest). ``forward`` gives what a reduction onto I needs of b: ``q = b_R' A_RR^-1 b_R``
  and the reduced right-hand side ``g = b_I - A_IR A_RR^-1 b_R``; ``backward`` completes a given
  x_I to ``x_R = A_RR^-1 (b_R - A_RI x_I)``. With PARDISO each is one half of a solve (its
  forward and backward substitutions); the generic version costs one whole solve each.
* ``info``: backend name, factor size / memory where the backend reports it, seconds per phase.
* ``free()``: release the factor.

A new backend (e.g. a GPU one) is one more module with a :class:`Backend` subclass registered
in :mod:`dualfem.numerics.factor`.
"""
from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import scipy.linalg as dla
import scipy.sparse as sp

#: an order of all unknowns (a permutation, local unknowns last) or a function computing it lazily
OrderHint = np.ndarray | Callable[[], np.ndarray] | None


class Forward(NamedTuple):
    """The forward half of a solve with b, split at the Schur set I (R = the other unknowns).

    ``q = b_R' A_RR^-1 b_R`` (>= 0), ``g = b_I - A_IR A_RR^-1 b_R`` (in the order of ``local``), and
    ``state``: the backend's intermediate vector (n,) that :meth:`Factorization.backward` completes.
    ``state`` is linear in b and does not depend on b_I (the forward half of -b is ``-state``).
    So ``b' A^-1 b = q + g' S^-1 g`` and ``(A^-1 b)_I = S^-1 g`` with S the Schur complement.
    """

    q: float
    g: np.ndarray
    state: np.ndarray


class Factorization(ABC):
    """Factorization of one SPD sparse matrix (see module docstring for the phases)."""

    backend: str = "?"

    def __init__(self, local: np.ndarray | None = None, order: OrderHint = None):
        self.local = np.zeros(0, np.int64) if local is None else np.asarray(local, np.int64).ravel()
        self._order = order
        self.n = 0
        self.info: dict = {"backend": self.backend, "time_s": {}}
        self._schur: np.ndarray | None = None      # Schur onto self.local (in self.local's order)
        self.factorized = False

    # ----------------------------------------------------------------- phases
    @abstractmethod
    def _analyze(self, A: sp.csr_matrix) -> None: ...

    @abstractmethod
    def _factorize(self, A: sp.csr_matrix) -> None: ...

    @abstractmethod
    def _solve(self, b: np.ndarray) -> np.ndarray: ...

    def analyze(self, A: sp.spmatrix) -> Factorization:
        """Ordering + symbolic factorization of the pattern of ``A`` (values unused)."""
        A = _square_csr(A)
        self.n = A.shape[0]
        if self.local.size and (self.local.min() < 0 or self.local.max() >= self.n
                                or np.unique(self.local).size != self.local.size):
            raise ValueError(f"local indices must be distinct and in [0, {self.n})")
        with _timer(self, "analyze"):
            self._analyze(A)
        self._pattern = (A.indptr.copy(), A.indices.copy())
        return self

    def factorize(self, A: sp.spmatrix) -> Factorization:
        """Numeric factorization of ``A`` (same pattern as at :meth:`analyze`; analyzes if not yet)."""
        A = _square_csr(A)
        if self.n == 0 and A.shape[0]:
            self.analyze(A)
        elif not (np.array_equal(A.indptr, self._pattern[0]) and np.array_equal(A.indices, self._pattern[1])):
            raise ValueError("factorize: the sparsity pattern differs from the analyzed one")
        self._schur = None
        with _timer(self, "factorize"):
            self._factorize(A)
        self.factorized = True
        return self

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``A^-1 b`` for b of shape (n,) or (n, k)."""
        if not self.factorized:
            raise RuntimeError("solve before factorize")
        b = np.asarray(b, float)
        if b.shape[0] != self.n or b.ndim not in (1, 2):
            raise ValueError(f"right-hand side of shape {b.shape}: expected ({self.n},) or ({self.n}, k)")
        if b.ndim == 2 and b.shape[1] == 0:
            return np.zeros_like(b)
        return self._solve(b)

    def schur(self, local: np.ndarray | None = None) -> np.ndarray:
        """Dense Schur complement onto ``local`` (default: the set declared at construction)."""
        if not self.factorized:
            raise RuntimeError("schur before factorize")
        want = self.local if local is None else np.asarray(local, np.int64).ravel()
        if want.size == 0:
            return np.zeros((0, 0))
        if self.local.size == want.size and np.array_equal(np.sort(self.local), np.sort(want)):
            if self._schur is None:
                with _timer(self, "schur"):
                    self._schur = self._own_schur()
            pos = np.empty(self.n, np.int64)
            pos[self.local] = np.arange(self.local.size)
            p = pos[want]
            return self._schur[np.ix_(p, p)]
        with _timer(self, "schur"):
            return schur_by_solves(self.solve, self.n, want)

    def _own_schur(self) -> np.ndarray:
        """Schur complement onto ``self.local`` in that order; backends override with their fast path."""
        return schur_by_solves(self.solve, self.n, self.local)

    def forward(self, b: np.ndarray) -> Forward:
        """The forward half of a solve with the 1-D ``b``, split at ``local`` (see :class:`Forward`)."""
        b = self._check_vector(b)
        return self._forward(b)

    def backward(self, fwd: Forward, x_local: np.ndarray) -> np.ndarray:
        """x with ``x[local] = x_local`` and ``x_R = A_RR^-1 (b_R - A_RI x_local)`` for the b of ``fwd``
        (so x = A^-1 b when x_local = S^-1 fwd.g)."""
        x_local = np.asarray(x_local, float)
        if x_local.shape != (self.local.size,) or np.shape(fwd.state) != (self.n,):
            raise ValueError(f"backward: x_local of shape {x_local.shape} for {self.local.size} local unknowns")
        return self._backward(fwd, x_local)

    def _forward(self, b: np.ndarray) -> Forward:
        """Generic: one whole solve u = A^-1 b; g = S u_I, q = b'u - u_I'g; state = b with g taken off b_I."""
        u = self.solve(b)
        uI = u[self.local]
        g = self.schur() @ uI if self.local.size else np.zeros(0)
        state = b.copy()
        state[self.local] -= g
        return Forward(max(float(b @ u - uI @ g), 0.0), g, state)

    def _backward(self, fwd: Forward, x_local: np.ndarray) -> np.ndarray:
        """Generic: one whole solve with ``state + S x_local`` on I (its b_I that makes x_I = x_local)."""
        v = np.array(fwd.state, float)
        if self.local.size:
            v[self.local] += self.schur() @ x_local
        x = self.solve(v)
        x[self.local] = x_local
        return x

    def _check_vector(self, b: np.ndarray) -> np.ndarray:
        if not self.factorized:
            raise RuntimeError("solve before factorize")
        b = np.asarray(b, float)
        if b.shape != (self.n,):
            raise ValueError(f"right-hand side of shape {b.shape}: expected ({self.n},)")
        return b

    def free(self) -> None:
        """Release the factor (the object can be factorized again after :meth:`analyze`)."""
        self.factorized = False
        self._schur = None

    def order(self) -> np.ndarray | None:
        """The order hint given at construction, evaluated (None if none was given)."""
        if callable(self._order):
            self._order = np.asarray(self._order(), np.int64)
        return self._order


class Backend(ABC):
    """A factorization library. ``make(local, order)`` returns an un-analyzed :class:`Factorization`."""

    name: str = "?"
    #: pip requirement that installs it (shown in error messages)
    install_hint: str = ""
    #: True: a direct factorization (exact to rounding, Schur complements; what ``factor=`` names). False: an
    #: inexact K-solve (AMG-preconditioned CG) that the dual operator and the certificate use where no
    #: factorization fits, its residuals recorded (:mod:`dualfem.numerics.amg`)
    direct: bool = True
    #: the entry of :data:`dualfem.numerics.memory.CALIBRATION` whose fit models this backend's factor
    #: (default: its own name; CHOLMOD, not measured, is modelled as PARDISO)
    memory_model: str = ""

    @classmethod
    @abstractmethod
    def available(cls) -> bool:
        """True if the library imports here."""

    @classmethod
    def missing(cls) -> str | None:
        """None when the backend can run here, else why not and how to install it (one sentence)."""
        if cls.available():
            return None
        return f"{cls.name} is not installed here; install it with: {cls.install_hint}"

    def multi_factor(self, keep: int) -> Factorization | None:
        """A factorization object that keeps ``keep`` numeric factors of one analyzed pattern (one analysis
        for all; ``slot(k)`` selects the factor the next ``factorize`` writes and ``solve`` uses), or None
        where the library has none (the caller then keeps one object per factor)."""
        return None

    # ---------------------------------------------------- the non-direct (iterative) K-solves (direct = False)
    @classmethod
    def default_rtol(cls) -> float:
        """The relative residual of an iterative backend's K-solves when nobody asks for another."""
        raise NotImplementedError(f"{cls.name} is a direct factorization")

    @classmethod
    def inner_rtol(cls, outer_tol: float) -> float:
        """The K-solve's relative residual for a dual solver that declares the relative tolerance ``outer_tol``."""
        raise NotImplementedError(f"{cls.name} is a direct factorization")

    @classmethod
    def for_qp(cls, qp, store=None):
        """The iterative K-solver of ``qp.K`` (made once per :class:`~dualfem.numerics.linalg.FactorStore`):
        ``solve(b, x0=None, rtol=None)``, ``last_abs`` (true residuals of the last solve), ``lambda_min()``,
        ``counters``, ``info``."""
        raise NotImplementedError(f"{cls.name} is a direct factorization")

    @classmethod
    def require(cls) -> None:
        """MissingDependency (its install hint) unless the backend can run here."""
        missing = cls.missing()
        if missing is not None:
            from dualfem.core.errors import MissingDependency

            raise MissingDependency(missing)

    @classmethod
    def peak_bytes(cls, n_unknowns: int, dim: int = 2, analysis: dict | None = None) -> int:
        """Extra peak RSS (bytes) of factorizing K with ``n_unknowns`` unknowns in ``dim`` dimensions in a
        process that already holds the QP (the backend's memory model; ``analysis``: a factorization's
        ``info`` after its analysis, whose ``peak_bytes`` replaces the model where the library reports it)."""
        from dualfem.numerics.memory import direct_factor_bytes

        return direct_factor_bytes(n_unknowns, cls.memory_model or cls.name, analysis, dim)

    @abstractmethod
    def make(self, local: np.ndarray | None = None, order: OrderHint = None) -> Factorization: ...

    def factor(self, A: sp.spmatrix, local: np.ndarray | None = None, order: OrderHint = None) -> Factorization:
        """analyze + factorize in one call."""
        return self.make(local, order).analyze(A).factorize(A)


def schur_by_solves(solve: Callable[[np.ndarray], np.ndarray], n: int, local: np.ndarray) -> np.ndarray:
    """Schur complement onto ``local`` of an SPD A from |I| solves: ``S = ((A^-1)_II)^-1``."""
    E = np.zeros((n, local.size))
    E[local, np.arange(local.size)] = 1.0
    W = solve(E)[local]
    W = 0.5 * (W + W.T)
    S = dla.cho_solve(dla.cho_factor(W, lower=True), np.eye(local.size))
    return 0.5 * (S + S.T)


def _square_csr(A: sp.spmatrix) -> sp.csr_matrix:
    A = sp.csr_matrix(A, dtype=float)
    if A.shape[0] != A.shape[1]:
        raise ValueError(f"matrix must be square, got shape {A.shape}")
    if not A.has_canonical_format:      # sorted, no duplicates (PARDISO needs both); never touch the caller's
        A = A.copy()
        A.sum_duplicates()
    return A


class _timer:
    def __init__(self, f: Factorization, key: str):
        self.f, self.key = f, key

    def __enter__(self):
        self.t0 = time.perf_counter()

    def __exit__(self, *exc):
        ts = self.f.info.setdefault("time_s", {})
        ts[self.key] = ts.get(self.key, 0.0) + time.perf_counter() - self.t0
        return False
