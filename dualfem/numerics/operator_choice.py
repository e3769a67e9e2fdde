"""Which dual operator a QP gets: the memory each would need and the choice (auto: dense while the local
unknowns are few and the dense blocks fit, else matrix-free with one factorization of K, else matrix-free with
AMG K-solves). Split from :mod:`dualfem.numerics.dual_operator` (which re-exports every name); the
linear-algebra context (:mod:`dualfem.numerics.la`) calls :func:`choose_operator` with its backend and its
memory budget.

Sizes in unknowns, memory in bytes (estimates x :data:`dualfem.numerics.memory.SAFETY`)."""
from __future__ import annotations

import numpy as np

from dualfem.core.errors import InputError
from dualfem.core.qp import QP
from dualfem.numerics.factor import registered

#: the dual-operator kinds (``operator=`` of the dual solvers)
OPERATORS = ("auto", "dense", "matrix_free", *registered(direct=False))
#: ``auto`` takes the dense reduction while |I|^2 <= CROSSOVER_RATIO * n (n unknowns, |I| local unknowns):
#: the dense phases cost ~|I|^3 flops and a 2D sparse factorization ~n^1.5, so the crossover is a ratio
#: of |I|^2 to n (the crossover measured: benchmarks/results/operator_crossover.md, docs/measurements.md)
CROSSOVER_RATIO = 32.0
#: and never more local unknowns than this on the dense path (tests lower it to force matrix-free)
CROSSOVER_LOCAL = 12000


def check_operator(value, solver: str) -> str:
    """The operator name of a solver parameter (``matrixfree``, the old spelling, is accepted)."""
    v = str(value).strip().lower()
    if v == "matrixfree":
        v = "matrix_free"
    if v not in OPERATORS:
        raise InputError(f"parameter 'operator' of solver {solver!r} must be one of {', '.join(OPERATORS)}, "
                         f"got {value!r}")
    return v


def dense_extra_bytes(n_local: int, m: int) -> int:
    """Memory of the dense path beyond the factorization: S_I and its Cholesky factor (|I|^2 each),
    V = L^-1 B_I' (|I| m) and D (m^2), 8 bytes each."""
    return 8 * (2 * n_local * n_local + n_local * m + m * m)


def qp_dim(qp: QP) -> int:
    """The QP's space dimension (``geometry.dim``; 2 without a geometry)."""
    return int(qp.geometry.dim) if qp.geometry is not None else 2


def estimates(qp: QP, backend: str | None = None, ksolve: str = "amg") -> dict:
    """Extra peak memory (bytes, x the model's SAFETY) of each operator for a QP the process already holds:
    the factorization (:func:`dualfem.numerics.memory.factor_bytes`, of the QP's dimension) plus, dense, the
    dense blocks (:func:`dense_extra_bytes`), matrix-free, a few n-vectors; under the name of the non-direct
    K-solve backend ``ksolve`` (``amg``): its memory model (:meth:`~dualfem.numerics.factor.base.Backend.
    peak_bytes`, the AMG hierarchy) and a few n-vectors. Compared with the memory available now."""
    from dualfem.numerics.factor import backend_class, get_default
    from dualfem.numerics.memory import SAFETY, factor_bytes

    backend = backend or get_default()
    base = factor_bytes(max(qp.n, 1), backend, dim=qp_dim(qp))
    nI = int(np.asarray(qp.local_dofs).size)
    return {"dense": int(SAFETY * (base + dense_extra_bytes(nI, qp.m))),
            "matrix_free": int(SAFETY * (base + 8 * 8 * qp.n)),
            ksolve: int(SAFETY * (backend_class(ksolve).peak_bytes(max(qp.n, 1)) + 8 * 16 * qp.n))}


def choose_operator(qp: QP, asked: str = "auto", limit_bytes: int | None = None,
                    backend: str | None = None, ksolve: str = "amg") -> tuple[str, str]:
    """(operator, why) for ``asked`` in :data:`OPERATORS`.

    ``auto``: dense while |I|^2 <= :data:`CROSSOVER_RATIO` n and |I| <= :data:`CROSSOVER_LOCAL` (and <=
    MAX_LOCAL) and its estimate fits the memory available (``limit_bytes``), else matrix-free (one
    factorization of K by ``backend``) if that fits, else the matrix-free operator on the non-direct K-solve
    backend ``ksolve`` (kind: its name, ``amg``) if installed and fitting. InputError when the asked one (or,
    for auto, none) fits, naming the sizes, the estimates, the memory and the other operator;
    MissingDependency when the asked K-solve backend is not installed.
    """
    from dualfem.numerics.factor import backend_class, registered
    from dualfem.numerics.linalg import MAX_LOCAL
    from dualfem.numerics.memory import available_bytes

    asked = check_operator(asked, "?") if asked not in OPERATORS else asked
    ks = asked if asked in registered(direct=False) else ksolve
    kb = backend_class(ks)
    nI = int(np.asarray(qp.local_dofs).size)
    est = estimates(qp, backend, ks)
    have = available_bytes() if limit_bytes is None else int(limit_bytes)
    sizes = f"n = {qp.n} unknowns, {nI} local unknowns, m = {qp.m}"

    def refuse(kind: str, other: str) -> InputError:
        return InputError(f"operator={kind}: {sizes}: needs about {est[kind] / 1e9:.1f} GB, available "
                          f"{have / 1e9:.1f} GB; operator={other} needs about {est[other] / 1e9:.1f} GB")

    if asked == ks:
        kb.require()
        if est[ks] > have:
            raise refuse(ks, "matrix_free")
        return ks, "asked"
    if asked == "dense":
        if nI > MAX_LOCAL:
            raise InputError(f"operator=dense: {sizes}: the dense reduced matrix would exceed {MAX_LOCAL}^2 "
                             f"(about {est['dense'] / 1e9:.1f} GB); use operator=matrix_free "
                             f"(about {est['matrix_free'] / 1e9:.1f} GB)")
        if est["dense"] > have:
            raise refuse("dense", "matrix_free")
        return "dense", "asked"
    if asked == "matrix_free":
        if est["matrix_free"] > have:
            raise refuse("matrix_free", ks)
        return "matrix_free", "asked"
    limit = int(min(CROSSOVER_LOCAL, MAX_LOCAL, np.sqrt(CROSSOVER_RATIO * qp.n)))
    if nI <= limit and est["dense"] <= have:
        return "dense", f"auto: {nI} local unknowns <= {limit}"
    if est["matrix_free"] <= have:
        return "matrix_free", f"auto: {nI} local unknowns > {limit}" if nI > limit \
            else "auto: the dense blocks do not fit in memory"
    missing = kb.missing()
    if est[ks] <= have and missing is None:
        return ks, (f"auto: no factorization of K fits ({est['matrix_free'] / 1e9:.1f} GB estimated, "
                    f"{have / 1e9:.1f} GB available)")
    hint = "" if missing is None else f" (operator={ks}: {missing})"
    raise InputError(f"operator=auto: {sizes}: neither operator fits: dense about {est['dense'] / 1e9:.1f} GB, "
                     f"matrix_free about {est['matrix_free'] / 1e9:.1f} GB, {ks} about {est[ks] / 1e9:.1f} GB, "
                     f"available {have / 1e9:.1f} GB{hint}")
