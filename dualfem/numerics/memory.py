"""Peak memory of a solve from the number of unknowns and the factorization backend.

A model calibrated on measured runs of the f2 scene (plane strain, delta = 1e-5; peak RSS of
one process that builds the QP, factorizes K_fixed with the Schur complement onto the defect
unknowns and solves once: benchmarks/factor_backends.py, results in
benchmarks/results/factor/):

    peak(n) = max( build_peak(n),  held(n) + factor_peak(n) )

* ``build_peak(n) = a + b n``: peak RSS of the scene -> QP assembly (the import baseline included);
* ``held(n) = a + b n``: RSS the QP keeps afterwards;
* ``factor_peak(n) = c n log2(n)`` per backend: the measured RSS increase of the factorization
  with the Schur block (superlu: the LU, the permuted matrix, the trailing blocks read for the
  Schur block; pardiso: its factor, its copy of the upper triangle, the dense Schur block). Given
  PARDISO's own analysis report (max(iparm[14], iparm[15] + iparm[16]) KiB, ``analysis=``),
  :func:`estimate_peak_bytes` uses it, scaled by the measured RSS/report ratio, instead.

In 3D (``dim=3``) a factorization grows faster: nnz(L) ~ c n^1.42 (nested dissection of a 3D mesh;
the points of CALIBRATION_3D, PARDISO/METIS on the unit cube, clamped base, P1 tetrahedra), so
``factor_peak_3d(n) = BYTES_PER_NNZ_L x nnz_L(n)``; the build is modelled as the 2D build with
:data:`BUILD_3D_FACTOR` times the per-unknown slope (a P1 tetrahedral K has ~81 entries per row
against 18 in 2D). Where no factorization fits, the AMG K-solve (:mod:`dualfem.numerics.amg`) needs
about :data:`AMG_BYTES_PER_UNKNOWN` per unknown (:func:`amg_bytes`).

Least-squares fits of the points in CALIBRATION (so adding a measured point refines the model).
The iterations and the certification of the exact solvers work on m x m dense blocks and add
little; they are not in the model. :func:`fits` applies a SAFETY margin. CHOLMOD, not measured
here, is modelled as PARDISO (a supernodal Cholesky of the same size).
"""
from __future__ import annotations

import functools

import numpy as np

from dualfem.core import limits
from dualfem.core.errors import InputError
from dualfem.numerics.factor import get_default

MB = 2**20
#: measured (n unknowns, peak RSS of the build, RSS held by the QP; factor's extra peak) in MB.
#: build and pardiso: benchmarks/results/factor/memory_calibration.md (f2, N = 64 ... 2048, one
#: worker process per N; pardiso = RSS after the Schur factorization + solve minus the RSS held by
#: the QP: PARDISO's factor, its copy of the upper triangle and the dense Schur block);
#: superlu: RSS increase of factor_fixed + solve (benchmarks/results/factor/factor_backends.md)
CALIBRATION = {
    "build": [(8382, 87, 81), (33150, 121, 90), (131838, 252, 130), (525822, 775, 288),
              (2100222, 2885, 864), (8394750, 11142, 2945)],
    "superlu": [(8382, 112 - 91), (33150, 227 - 132), (131838, 750 - 307), (525822, 3027 - 610)],
    "pardiso": [(8382, 100 - 81), (33150, 154 - 90), (131838, 366 - 130), (525822, 1199 - 288),
                (2100222, 4458 - 864), (8394750, 18021 - 2945)],
}
#: PARDISO's own analysis report (max(iparm[14], iparm[15] + iparm[16]), MB) against the measured
#: RSS increase above (same runs): the report is scaled by the largest ratio of the runs with
#: n >= 1e5 (1.42 at N = 256; 1.20 at N = 2048) when it refines the estimate
PARDISO_REPORT = [(131838, 166, 236), (525822, 671, 911), (2100222, 2927, 3594), (8394750, 12597, 15076)]
#: 3D, P1 tetrahedra (unit cube, clamped base): (n unknowns, nnz(L) of PARDISO with METIS): 14 k, 45 k and
#: 148 k measured by iparm[17] here (tests/_three_d_qp.py, N = 16, 24, 36), 346 k from
#: /work/shared/notes/performance.md; the fit is ~6.6 n^1.42 (670 k: ~1.2e9 predicted)
CALIBRATION_3D = [(13872, 5.04e6), (45000, 2.69e7), (147852, 1.456e8), (346000, 4.8e8)]
#: bytes of peak RSS per entry of L: PARDISO's own peak report is 9-11 bytes per nnz(L) in 3D (N = 16, 24,
#: 36: 56 MB for 5.0e6, 271 MB for 2.7e7, 1.35 GB for 1.46e8), 8 bytes per value plus indices and its copy of
#: the matrix; the measured RSS increase of factor + solve at 148 k was 1.39 GB (10.0 bytes per entry), and
#: 5.7 GB at 346 k for the whole process (scikit-fem's assembly included) is below 12 x 4.8e8: 12 keeps ~20 %
BYTES_PER_NNZ_L = 12.0
#: the 3D build's per-unknown slope relative to the 2D fit (nnz per row of K: 81 against 18)
BUILD_3D_FACTOR = 4.5
#: extra peak of the AMG K-solve per unknown: the pyamg hierarchy (operator complexity ~1.5 with 6 rigid
#: modes: the tentative and smoothed prolongators hold 6 columns per aggregate) and CG's vectors. Measured
#: here (RSS increase of setup + one solve): 87 MB at 86 k unknowns, 333 MB at 148 k (2.25 kB per unknown);
#: /work/shared/notes/performance.md: 4.2 GB at 346 k and 8 GB at 670 k for the whole process (scikit-fem's
#: assembly included); 3 kB keeps a margin
AMG_BYTES_PER_UNKNOWN = 3072
#: multiply the estimate by this before comparing with the available memory (the least-squares
#: fit follows the large runs: 18.1 GB estimated for 18.0 GB measured at N = 2048; it
#: under-estimates N = 512 by 12 % and N = 256 (a 0.37 GB peak) by 13 %)
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
