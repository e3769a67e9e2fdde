"""Peak memory of a solve from the number of unknowns and the factorization backend.

A model fitted to the calibration points below (peak RSS, MB, of one process that builds the QP, factorizes
K_fixed with the Schur complement onto the defect unknowns and solves once; their sources and what they
showed: docs/measurements.md, section ``dualfem/numerics/memory.py``):

    peak(n) = max( build_peak(n),  held(n) + factor_peak(n) )        (bytes; n unknowns)

* ``build_peak(n) = a + b n``: peak RSS of the scene -> QP assembly (the import baseline included);
* ``held(n) = a + b n``: RSS the QP keeps afterwards;
* ``factor_peak(n) = c n log2(n)`` per backend: the RSS increase of the factorization with the Schur block.
  Given PARDISO's own analysis report (max(iparm[14], iparm[15] + iparm[16]) KiB, ``analysis=``),
  :func:`estimate_peak_bytes` uses it, scaled by the largest RSS/report ratio of PARDISO_REPORT, instead.

In 3D (``dim=3``) ``factor_peak_3d(n) = BYTES_PER_NNZ_L x nnz_L(n)`` with nnz(L) ~ c n^e fitted to
CALIBRATION_3D (nested dissection of a 3D mesh); the build is the 2D build with :data:`BUILD_3D_FACTOR`
times the per-unknown slope. Where no factorization fits, the AMG K-solve (:mod:`dualfem.numerics.amg`)
needs :data:`AMG_BYTES_PER_UNKNOWN` per unknown (:func:`amg_bytes`).

Least-squares fits of the points in CALIBRATION (so adding a point refines the model). The iterations and
the certification of the exact solvers work on m x m dense blocks and are not in the model. :func:`fits`
applies a SAFETY margin. CHOLMOD is modelled as PARDISO (a supernodal Cholesky of the same size).
"""
from __future__ import annotations

import functools

import numpy as np

from dualfem.core import limits
from dualfem.core.errors import InputError
from dualfem.numerics.factor import get_default

MB = 2**20
#: (n unknowns, peak RSS of the build, RSS held by the QP) and per backend (n, factor's extra peak), in MB, of f2
#: at delta = 1e-5: benchmarks/results/factor/memory_calibration.md and factor_backends.md
CALIBRATION = {
    "build": [(8382, 87, 81), (33150, 121, 90), (131838, 252, 130), (525822, 775, 288),
              (2100222, 2885, 864), (8394750, 11142, 2945)],
    "superlu": [(8382, 112 - 91), (33150, 227 - 132), (131838, 750 - 307), (525822, 3027 - 610)],
    "pardiso": [(8382, 100 - 81), (33150, 154 - 90), (131838, 366 - 130), (525822, 1199 - 288),
                (2100222, 4458 - 864), (8394750, 18021 - 2945)],
}
#: (n, PARDISO's analysis report, the RSS increase of CALIBRATION's same run) in MB; the report is scaled by the
#: largest ratio of the runs with n >= 1e5 (source: benchmarks/results/factor/memory_calibration.md)
PARDISO_REPORT = [(131838, 166, 236), (525822, 671, 911), (2100222, 2927, 3594), (8394750, 12597, 15076)]
#: 3D, P1 tetrahedra on the unit cube, clamped base: (n unknowns, nnz(L) of PARDISO with METIS), from
#: PARDISO's iparm[17] (tests/_three_d_qp.py) and /work/shared/notes/performance.md (docs/measurements.md)
CALIBRATION_3D = [(13872, 5.04e6), (45000, 2.69e7), (147852, 1.456e8), (346000, 4.8e8)]
#: bytes of peak RSS per entry of L in 3D (values, indices and PARDISO's copy of the matrix, with a margin)
BYTES_PER_NNZ_L = 12.0
#: the 3D build's per-unknown slope relative to the 2D fit (nnz per row of K: 81 against 18)
BUILD_3D_FACTOR = 4.5
#: extra peak of the AMG K-solve per unknown, bytes: the pyamg hierarchy with 6 rigid-body modes and CG's
#: vectors, with a margin
AMG_BYTES_PER_UNKNOWN = 3072
#: multiply the estimate by this before comparing with the available memory
SAFETY = 1.15

@functools.cache
def _coefficients() -> dict:
    build = np.array(CALIBRATION["build"], float)
    A = np.column_stack([np.ones(len(build)), build[:, 0]])
    coef = {"build_peak": np.linalg.lstsq(A, build[:, 1], rcond=None)[0],
            "held": np.linalg.lstsq(A, build[:, 2], rcond=None)[0]}
    for b in (k for k in CALIBRATION if k != "build"):
        pts = np.array(CALIBRATION[b], float)
        x = pts[:, 0] * np.log2(pts[:, 0])
        coef[b] = float(x @ pts[:, 1] / (x @ x))          # MB per n log2 n, through the origin
    p3 = np.array(CALIBRATION_3D, float)
    A3 = np.column_stack([np.ones(len(p3)), np.log(p3[:, 0])])
    coef["nnz_l_3d"] = np.linalg.lstsq(A3, np.log(p3[:, 1]), rcond=None)[0]     # log c, exponent
    coef["pardiso_report"] = max(rss / rep for n, rep, rss in PARDISO_REPORT if n >= 1e5)
    return coef


def _check_dim(dim: int) -> int:
    if dim not in (2, 3):
        raise InputError(f"dim must be 2 or 3, got {dim!r}")
    return int(dim)


def build_bytes(n_unknowns: int, dim: int = 2) -> tuple[int, int]:
    """(peak RSS of the build, RSS the QP holds afterwards) in bytes, for n unknowns in ``dim`` dimensions."""
    c, n = _coefficients(), int(n_unknowns)
    k = BUILD_3D_FACTOR if _check_dim(dim) == 3 else 1.0
    return (int((c["build_peak"][0] + k * c["build_peak"][1] * n) * MB),
            int((c["held"][0] + k * c["held"][1] * n) * MB))


def estimate_peak_bytes(n_unknowns: int, backend: str = "pardiso", analysis: dict | None = None,
                        dim: int = 2) -> int:
    """Estimated peak RSS (bytes) of building and factorizing a QP with n unknowns in ``dim`` dimensions.

    ``analysis``: a factorization's ``info`` after its analysis phase; PARDISO's ``peak_bytes``
    replaces the model of the factor's peak. ``backend``: any registered one (``"amg"``: the AMG K-solve).
    """
    factor = factor_bytes(n_unknowns, backend, analysis, dim)
    build_peak, held = build_bytes(n_unknowns, dim)
    return int(max(build_peak, held + factor))


def nnz_l(n_unknowns: int, dim: int = 3) -> float:
    """Predicted entries of the Cholesky factor of K with nested dissection: 3D, the fit c n^1.42 of
    CALIBRATION_3D; 2D, the factor model divided by BYTES_PER_NNZ_L (an equivalent count)."""
    n = int(n_unknowns)
    if _check_dim(dim) == 3:
        lc, e = _coefficients()["nnz_l_3d"]
        return float(np.exp(lc) * max(n, 1) ** e)
    return direct_factor_bytes(n, "pardiso") / BYTES_PER_NNZ_L


def factor_bytes(n_unknowns: int, backend: str = "pardiso", analysis: dict | None = None, dim: int = 2) -> int:
    """Estimated extra peak RSS (bytes) of factorizing a QP with n unknowns that the process already holds
    (the ``factor_peak`` part of the model, without the build and the QP itself; ``analysis`` as in
    :func:`estimate_peak_bytes`): the registered backend's own model (:meth:`Backend.peak_bytes
    <dualfem.numerics.factor.base.Backend.peak_bytes>`; the direct ones: :func:`direct_factor_bytes`, the
    AMG K-solve: :func:`amg_bytes`). InputError for an unknown backend."""
    from dualfem.numerics.factor import backend_class

    n = int(n_unknowns)
    if n < 1:
        raise InputError(f"n_unknowns must be >= 1, got {n_unknowns!r}")
    return int(backend_class(backend, "backend").peak_bytes(n, dim, analysis))


def direct_factor_bytes(n_unknowns: int, model: str, analysis: dict | None = None, dim: int = 2) -> int:
    """The model of a direct factorization's extra peak (bytes) fitted to ``CALIBRATION[model]``.

    ``dim=3``: BYTES_PER_NNZ_L x :func:`nnz_l` scaled by the 2D ratio of the model's coefficient to PARDISO's
    (SuperLU not measured in 3D); ``analysis["peak_bytes"]`` (PARDISO's report), when given, replaces the model."""
    n = int(n_unknowns)
    if n < 1:
        raise InputError(f"n_unknowns must be >= 1, got {n_unknowns!r}")
    c = _coefficients()
    if model not in c:
        raise InputError(f"no memory model {model!r} for the backend (calibrated: "
                         f"{', '.join(k for k in CALIBRATION if k != 'build')})")
    if analysis and analysis.get("peak_bytes"):
        return int(c["pardiso_report"] * analysis["peak_bytes"])
    if _check_dim(dim) == 3:
        return int(BYTES_PER_NNZ_L * nnz_l(n, 3) * c[model] / c["pardiso"])
    return int(c[model] * n * np.log2(max(n, 2)) * MB)


def amg_bytes(n_unknowns: int) -> int:
    """Estimated extra peak RSS (bytes) of the AMG K-solve (hierarchy + CG) of a QP the process holds."""
    n = int(n_unknowns)
    if n < 1:
        raise InputError(f"n_unknowns must be >= 1, got {n_unknowns!r}")
    return int(AMG_BYTES_PER_UNKNOWN * n)


def available_bytes() -> int:
    """Memory available for a new process now: the smallest of the machine's ``MemAvailable``, the
    address space left under ``ulimit -v`` and the room in the process's memory cgroups (v1 and v2):
    :func:`dualfem.core.limits.available_bytes`."""
    return limits.available_bytes()


def fits(n_unknowns: int, backend: str = "pardiso", limit_bytes: int | None = None,
         analysis: dict | None = None, dim: int = 2) -> tuple[bool, int, int]:
    """(fits, SAFETY x estimate, limit): limit defaults to :func:`available_bytes`."""
    est = int(SAFETY * estimate_peak_bytes(n_unknowns, backend, analysis, dim))
    lim = available_bytes() if limit_bytes is None else int(limit_bytes)
    return est <= lim, est, lim


def amg_installed() -> bool:
    """True when pyamg (the ``amg`` extra) can be imported."""
    import importlib.util

    return importlib.util.find_spec("pyamg") is not None


def _problem_dim(problem, est: tuple) -> int:
    """The scene's dimension: a third entry of ``size_estimate()``, else ``problem.dim``, else
    ``problem.params["dim"]``, else 2."""
    if len(est) > 2:
        return int(est[2])
    d = getattr(problem, "dim", None)
    if d is None and isinstance(getattr(problem, "params", None), dict):
        d = problem.params.get("dim")
    try:
        return 3 if int(d) == 3 else 2
    except (TypeError, ValueError):
        return 2


def check_fits(problem, max_bytes: float | None = None, backend: str | None = None) -> None:
    """InputError naming the size, the estimate and the memory when a scene cannot fit (before assembly).
    3D scenes (:func:`_problem_dim`) use the 3D factor model and pass when the AMG K-solve fits."""

    from dualfem.numerics.factor import backend_class
    from dualfem.numerics.la import current

    est = problem.size_estimate() if hasattr(problem, "size_estimate") else None
    if est is None:
        return
    n, label = est[0], est[1]
    backend = backend or get_default()
    dim = _problem_dim(problem, est)
    limit = None if max_bytes is None else int(max_bytes)
    ok, need, have = fits(n, backend, limit, dim=dim)
    ks = backend_class(current().ksolve)             # the context's non-direct K-solve (AMG)
    if not ok and dim == 3 and ks.missing() is None:  # 3D: where no factorization fits, the AMG K-solve may
        ok = fits(n, ks.name, limit, dim=3)[0]
    if not ok:
        alt = ""
        if dim == 3:
            alt = (f" or about {fits(n, ks.name, limit, dim=3)[1] / 1e9:.0f} GB with the {ks.name} K-solve"
                   + ("" if ks.missing() is None else f" ({ks.install_hint})"))
        raise InputError(f"{label} ({n / 1e6:.1f} M unknowns) needs about {need / 1e9:.0f} GB of memory with the "
                         f"{backend} factorization{alt} (estimate x {SAFETY:g}), "
                         f"{'allowed' if max_bytes is not None else 'available'}: {have / 1e9:.1f} GB; use a smaller "
                         f"size, or --max-memory GB to override")
