"""Thread counts for the sparse factorization (MKL PARDISO) and the dense phases (OpenBLAS), via threadpoolctl.

``set_threads(n)`` (default n: every core this process may use) gives MKL -- the library
PARDISO runs in, loaded by pypardiso -- n threads, and numpy's/scipy's OpenBLAS, which runs the
dense m x m phases, ``min(DENSE_THREADS, n)``; it exports ``MKL_NUM_THREADS``/``OMP_NUM_THREADS``
= n and ``OPENBLAS_NUM_THREADS`` for worker processes. :func:`ensure_threads` applies the default
once (called by :func:`dualfem.numerics.linalg.factor_fixed`). ``threads(n)`` sets every pool to n
temporarily (context manager). If numpy itself were linked to MKL the dense phases would follow n.

The dense m x m phases (Cholesky of the Schur block S, D = B_I S^-1 B_I', S @ v in every
iteration) use DENSE_THREADS = 1 (two OpenBLAS threads that compete with other busy threads spin; one
thread never does); PARDISO keeps every core. The measurements behind both: docs/measurements.md.
:func:`set_threads` loads pypardiso's MKL first so that threadpoolctl sees it.
"""
from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

from dualfem.core.errors import InputError

#: threads for the dense m x m phases (the measurement: docs/measurements.md)
DENSE_THREADS = 1
_LIMITER = None
_CURRENT: int | None = None


def cpu_count() -> int:
    """Cores this process may run on (the affinity mask, not the machine's total)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:                       # not Linux
        return os.cpu_count() or 1


def _check(n: int | None) -> int:
    if n is None:
        return cpu_count()
    try:
        k = int(n)
    except (TypeError, ValueError):
        raise InputError(f"threads must be a positive integer, got {n!r}") from None
    if k != n or k < 1:
        raise InputError(f"threads must be a positive integer, got {n!r}")
    return k


def _load_libraries() -> None:
    """Load MKL (through pypardiso) so that threadpoolctl sees it."""
    try:
        from .factor.pardiso import _lib

        _lib()
    except (ImportError, OSError):
        pass


def set_threads(n: int | None = None) -> int:
    """n threads (default: all cores) for PARDISO/MKL, min(DENSE_THREADS, n) for OpenBLAS; returns n."""
    global _LIMITER, _CURRENT
    from threadpoolctl import threadpool_limits

    k = _check(n)
    dense = min(DENSE_THREADS, k)
    _load_libraries()
    os.environ.update({"OMP_NUM_THREADS": str(k), "MKL_NUM_THREADS": str(k), "OPENBLAS_NUM_THREADS": str(dense)})
    from threadpoolctl import threadpool_info

    per_lib = {d["filepath"]: dense if d.get("internal_api") in ("openblas", "blis") else k
               for d in threadpool_info()}
    _LIMITER = threadpool_limits(limits=per_lib)
    _CURRENT = k
    return k


def ensure_threads() -> int:
    """Apply the default (:func:`set_threads` with all cores) unless threads were set already."""
    return _CURRENT if _CURRENT is not None else set_threads(None)


def get_threads() -> int:
    """Threads set by :func:`set_threads` (all cores if it was never called)."""
    return _CURRENT if _CURRENT is not None else cpu_count()


@contextlib.contextmanager
def threads(n: int | None) -> Iterator[int]:
    """Temporarily use n threads in BLAS, LAPACK and PARDISO."""
    from threadpoolctl import threadpool_limits

    k = _check(n)
    _load_libraries()
    with threadpool_limits(limits=k):
        yield k


@contextlib.contextmanager
def dense_threads() -> Iterator[int]:
    """Threads for the dense m x m phases: min(DENSE_THREADS, the process-wide count)."""
    with threads(min(DENSE_THREADS, get_threads())) as k:
        yield k


def info() -> list[dict]:
    """The loaded thread pools (library, API, threads), as threadpoolctl reports them."""
    from threadpoolctl import threadpool_info

    return [{"api": d.get("internal_api"), "threads": d.get("num_threads"), "library": d.get("filepath")}
            for d in threadpool_info()]
