"""The files of the public test set (:mod:`dualfem.experiments.testset`): the problem and reference
formats, and the check of a solver's answer against a certified reference (:func:`agreement`). The
manifest, README and qpbenchmark ``TestSet`` module: :mod:`dualfem.experiments.testset_render`.

``DIR/qp/NAME.npz`` (:func:`write_qp`): ``P`` and ``G`` as CSC arrays ``M_data``, ``M_indices``,
``M_indptr``, ``M_shape`` (``scipy.sparse.csc_matrix((data, indices, indptr), shape)``; P holds both
triangles), the vectors ``q`` and ``h``, ``name`` and ``convention`` (the string :data:`CONVENTION`).
No ``lb``/``ub``, no ``A``/``b``: the clamped unknowns are eliminated. qpsolvers' convention is
``G x <= h``, which is also how ``dualfem solve FILE`` reads ``P, q, G, h`` (problems/generic_qp.py), so
these files can be solved by every dualfem solver as they are.

``DIR/reference/NAME.npz`` (:func:`write_reference`): ``x`` (mm), ``z`` (qpsolvers' multipliers of
``G x <= h``: ``z = mu >= 0``, N per mm of thickness), ``objective`` (``1/2 x'Px + q'x``),
``certified_error`` (the certified relative energy-norm error of x, :func:`dualfem.numerics.certify.certified_error`).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from dualfem.core.errors import InputError
from dualfem.core.io import atomic_write

QP_DIR = "qp"
REF_DIR = "reference"
MANIFEST = "manifest.json"
README = "README.md"
#: the test-set module: qpbenchmark finds the class by the file name (``dualfem_contact`` -> ``DualfemContact``)
TESTSET_PY = "dualfem_contact.py"
TESTSET_CLASS = "DualfemContact"
FORMAT = "dualfem-testset/1"
CONVENTION = "qpsolvers: minimize 1/2 x'Px + q'x subject to G x <= h (P = K, q = -F, G = -B, h = 0)"
#: qpbenchmark's time limit per solve (s) written into the TestSet, by the largest size class it holds
RUNTIME = {"tiny": 10.0, "small": 10.0, "medium": 100.0, "large": 1000.0}
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,99}")


def check_name(name: str) -> str:
    """A problem name is a file stem: letters, digits, ``_ . + -``, at most 100 characters."""
    if not NAME_PATTERN.fullmatch(name) or name.endswith(".npz"):
        raise InputError(f"problem name {name!r} must be 1-100 letters, digits or _.+- (a file stem)")
    return name


def _csc_arrays(prefix: str, M: sp.spmatrix) -> dict[str, np.ndarray]:
    M = sp.csc_matrix(M)
    M.sort_indices()
    return {f"{prefix}_data": M.data, f"{prefix}_indices": M.indices.astype(np.int64),
            f"{prefix}_indptr": M.indptr.astype(np.int64), f"{prefix}_shape": np.array(M.shape, np.int64)}


def _csc(d: Any, prefix: str) -> sp.csc_matrix:
    return sp.csc_matrix((d[f"{prefix}_data"], d[f"{prefix}_indices"], d[f"{prefix}_indptr"]),
                         shape=tuple(int(s) for s in d[f"{prefix}_shape"]))


def _save(path: Path, arrays: dict[str, np.ndarray]) -> Path:
    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
    return atomic_write(path, write)


def write_qp(path: Path, name: str, P: sp.spmatrix, q: np.ndarray, G: sp.spmatrix, h: np.ndarray) -> Path:
    """Write one problem (see the module docstring), atomically."""
    return _save(path, {**_csc_arrays("P", P), "q": np.asarray(q, float), **_csc_arrays("G", G),
                        "h": np.asarray(h, float), "name": np.array(name), "convention": np.array(CONVENTION)})


def read_qp(path: str | Path) -> tuple[sp.csc_matrix, np.ndarray, sp.csc_matrix, np.ndarray]:
    """(P, q, G, h) of a file written by :func:`write_qp`."""
    with np.load(path, allow_pickle=False) as d:
        return _csc(d, "P"), np.array(d["q"]), _csc(d, "G"), np.array(d["h"])


@dataclass
class Reference:
    """A certified reference of one problem, in qpsolvers' convention (units: module docstring)."""

    x: np.ndarray
    z: np.ndarray
    objective: float
    certified_error: float


def write_reference(path: Path, name: str, x: np.ndarray, z: np.ndarray, objective: float,
                    info: dict[str, Any]) -> Path:
    """Write one reference (see the module docstring), atomically."""
    return _save(path, {"x": x, "z": z, "objective": np.array(objective),
                        "certified_error": np.array(info["certified_error"]), "name": np.array(name),
                        "solver": np.array(info["solver"]), "convention": np.array(CONVENTION)})


def read_reference(path: str | Path) -> Reference:
    """The :class:`Reference` of a file written by :func:`write_reference`."""
    with np.load(path, allow_pickle=False) as d:
        return Reference(np.array(d["x"]), np.array(d["z"]), float(d["objective"]), float(d["certified_error"]))


def kkt_residuals(P: sp.spmatrix, q: np.ndarray, G: sp.spmatrix, h: np.ndarray, x: np.ndarray,
                  z: np.ndarray) -> dict[str, float]:
    """The absolute KKT residuals of (x, z) as qpsolvers defines them for ``G x <= h`` (units of the data):
    primal ``max(0, max(Gx - h))``, dual ``|Px + q + G'z|_inf``, duality gap ``|x'Px + q'x + h'z|``, and
    the sign of z (``max(0, -min z)``) and complementarity (``max |z_j (Gx - h)_j|``) that qpsolvers leaves
    to the solver."""
    Px, Gx = P @ x, G @ x
    return {"primal": float(max(0.0, np.max(Gx - h, initial=0.0))),
            "dual": float(np.max(np.abs(Px + q + G.T @ z), initial=0.0)),
            "gap": float(abs(x @ Px + q @ x + h @ z)),
            "sign": float(max(0.0, -np.min(z, initial=0.0))),
            "complementarity": float(np.max(np.abs(z * (Gx - h)), initial=0.0))}


@dataclass
class Agreement:
    """How a solution (x, z) compares to a reference (units of the problem; see :func:`agreement`)."""

    objective_diff: float          # f(x) - f_ref
    objective_rel: float           # |f(x) - f_ref| / |f_ref|
    objective_range: tuple[float, float]   # the interval f(x) - f_ref must lie in
    x_dist: float                  # |x - x_ref|_P
    x_rel: float                   # |x - x_ref|_P / |x_ref|_P
    x_bound: float                 # the bound x_dist must not exceed
    reference_consistent: bool     # the reference's stored objective is the objective of its x
    ok: bool
    why: str


def _rounding(P: sp.spmatrix, q: np.ndarray, x: np.ndarray) -> float:
    """A bound on the rounding error of ``1/2 x'Px + q'x`` in double precision: 8 eps (|x|'|P||x| + |q|'|x|)."""
    ax = np.abs(x)
    return float(8 * np.finfo(float).eps * (ax @ (abs(P) @ ax) + np.abs(q) @ ax))


def agreement(P: sp.spmatrix, q: np.ndarray, G: sp.spmatrix, h: np.ndarray, ref: Reference,
              x: np.ndarray | None, z: np.ndarray | None) -> Agreement:
    """Does a solver's answer (x, z) agree with the certified reference ``ref`` of ``min 1/2 x'Px + q'x s.t.
    G x <= h``? The tolerance is the answer's own a-posteriori bound, from the residuals qpbenchmark records
    (no tolerance is chosen here):

    * with ``z >= 0`` (negative entries are set to 0) and ``r = P x + q + G'z``, weak duality gives
      ``f(x) - f* <= U = x'Px + q'x + h'z - r'x + 1/2 r'P^-1 r`` (the duality gap corrected for the dual
      residual), and ``f(x) - f* = 1/2 |x - x*|_P^2 + z*'(h - G x) >= -z*'s`` with ``s = max(G x - h, 0)``
      the primal violation (Taylor at x*, ``P x* + q = -G'z*``, complementarity);
    * so ``-z_ref's <= f(x) - f_ref <= U`` and ``|x - x_ref|_P <= sqrt(2 (U + z_ref's))``, each widened by
      the reference's own error (its certified relative energy-norm error c: ``c |x_ref|_P`` and
      ``c^2 |x_ref|_P^2`` plus its complementarity defect) and the rounding of the objectives (8 eps
      (|x|'|P||x| + |q|'|x|)).

    The reference must also be consistent: its stored objective is that of its own x (up to rounding).
    An answer without multipliers or not finite never agrees (no bound can be computed).
    """
    import scipy.sparse.linalg as sla

    f_ref_own = float(0.5 * ref.x @ (P @ ref.x) + q @ ref.x)
    rnd_ref = _rounding(P, q, ref.x)
    consistent = abs(f_ref_own - ref.objective) <= rnd_ref
    scale = max(abs(ref.objective), 1e-300)
    norm_ref = math.sqrt(max(float(ref.x @ (P @ ref.x)), 0.0))
    nan = math.nan
    if x is None or z is None or np.shape(x) != np.shape(ref.x) or np.shape(z) != np.shape(ref.z) \
            or not (np.all(np.isfinite(x)) and np.all(np.isfinite(z))):
        return Agreement(nan, nan, (nan, nan), nan, nan, nan, consistent, False,
                         "no finite solution with multipliers of the right size: nothing to bound")
    z = np.maximum(z, 0.0)
    Px = P @ x
    r = Px + q + G.T @ z
    upper = float(x @ Px + q @ x + h @ z - r @ x + 0.5 * r @ sla.spsolve(sp.csc_matrix(P), r))
    s = np.maximum(G @ x - h, 0.0)
    lower = -float(ref.z @ s)
    ref_err = ref.certified_error ** 2 * norm_ref ** 2 + float(np.abs(ref.z * (G @ ref.x - h)).sum())
    rnd = _rounding(P, q, x) + rnd_ref
    f = float(0.5 * x @ Px + q @ x)
    lo, hi = lower - ref_err - rnd, upper + ref_err + rnd
    d = x - ref.x
    x_dist = math.sqrt(max(float(d @ (P @ d)), 0.0))
    x_bound = math.sqrt(max(2 * (upper - lower + rnd), 0.0)) + ref.certified_error * norm_ref * (1 + 1e-12)
    why = []
    if not consistent:
        why.append(f"the reference's objective {ref.objective!r} is not that of its x ({f_ref_own!r})")
    if not lo <= f - ref.objective <= hi:
        why.append(f"f(x) - f_ref = {f - ref.objective:.3e} is outside [{lo:.3e}, {hi:.3e}]")
    if not x_dist <= x_bound:
        why.append(f"|x - x_ref|_P = {x_dist:.3e} > its bound {x_bound:.3e}")
    return Agreement(f - ref.objective, abs(f - ref.objective) / scale, (lo, hi), x_dist,
                     x_dist / max(norm_ref, 1e-300), x_bound, consistent, not why, "; ".join(why) or "agrees")
