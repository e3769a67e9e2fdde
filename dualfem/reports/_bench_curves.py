"""Convergence curves of a bench for the work-precision figures: median and quantile band across runs.

The input is the bench's curves table (``dualfem.results.load(DIR, table="curves")``), one row per
(run, sample) with exactly the columns ``run_id, solver, tier, scene_key, iteration, time_s, error,
error_kind`` (``time_s`` in seconds since the start of the run's setup, ``error`` relative,
dimensionless, of the kind ``error_kind``). :func:`curves_from_table` turns it (a pandas DataFrame or
any iterable of mappings with those keys) into typed :class:`Curve` objects; :func:`median_curve`
aggregates the curves of one (solver, scene, tier):

* a common grid of ``n_grid`` times, log-spaced from the earliest first sample to the latest last
  sample of the curves;
* each curve is interpolated linearly in (log10 time, log10 error) between its samples, is undefined
  (NaN) before its first sample and holds its last error after its last sample (the solver has
  returned: its answer stays what it is);
* at each grid time, the median and the quantiles (default 25 % and 75 %) are taken over the curves
  defined there, on log10 error (numpy's linear quantile of the logs: a geometric band), and
  returned as errors. Errors at or below 0 are floored at ``floor`` (1e-16), like the figure's points.
"""
from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from dualfem.core.errors import InputError

#: the columns of the curves table, exactly
CURVE_COLUMNS = ("run_id", "solver", "tier", "scene_key", "iteration", "time_s", "error", "error_kind")


@dataclass(frozen=True)
class Curve:
    """The samples of one run: ``time_s`` [s] increasing, ``error`` (relative, of ``error_kind``)."""

    run_id: str
    solver: str
    tier: str
    scene_key: str
    error_kind: str
    iteration: np.ndarray
    time_s: np.ndarray
    error: np.ndarray


@dataclass(frozen=True)
class MedianCurve:
    """Median and quantile band of ``n_curves`` curves on the grid ``time_s`` [s]; ``n_defined[i]``
    curves had started at ``time_s[i]`` (the statistics at i are over those)."""

    time_s: np.ndarray
    median: np.ndarray
    low: np.ndarray
    high: np.ndarray
    n_defined: np.ndarray
    n_curves: int
    quantiles: tuple[float, float]


def _records(table):
    if hasattr(table, "to_dict") and hasattr(table, "columns"):     # a pandas DataFrame
        missing = [c for c in CURVE_COLUMNS if c not in table.columns]
        if missing:
            raise InputError(f"the curves table lacks the columns {', '.join(missing)} "
                             f"(expected exactly {', '.join(CURVE_COLUMNS)})")
        return table[list(CURVE_COLUMNS)].to_dict("records")
    return list(table)


def _float(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def curves_from_table(table) -> list[Curve]:
    """One :class:`Curve` per run (per ``run_id``) of a curves table, in the order of first appearance.
    Samples with a non-finite or negative time or a non-finite error are dropped; a run's samples are
    sorted by (time, iteration). Empty table: []."""
    groups: dict[str, list[tuple[float, float, float]]] = defaultdict(list)
    meta: dict[str, tuple[str, str, str, str]] = {}
    for r in _records(table):
        try:
            rid = str(r["run_id"])
            key = (str(r["solver"]), str(r["tier"]), str(r["scene_key"]), str(r["error_kind"]))
            t, e, it = _float(r["time_s"]), _float(r["error"]), _float(r["iteration"])
        except KeyError as exc:
            raise InputError(f"a curves sample lacks the column {exc.args[0]!r} "
                             f"(expected {', '.join(CURVE_COLUMNS)})") from None
        meta.setdefault(rid, key)
        if math.isfinite(t) and t >= 0 and math.isfinite(e):
            groups[rid].append((t, it, e))
    out = []
    for rid, (solver, tier, scene_key, kind) in meta.items():
        s = sorted(groups.get(rid, []))
        if s:
            a = np.array(s, dtype=float)
            out.append(Curve(rid, solver, tier, scene_key, kind, a[:, 1], a[:, 0], a[:, 2]))
    return out


def _on_grid(c: Curve, lg: np.ndarray, floor: float) -> np.ndarray:
    """log10 error of one curve on the log10 time grid ``lg`` (NaN before its first sample)."""
    lt = np.log10(np.maximum(c.time_s, 1e-300))
    le = np.log10(np.maximum(c.error, floor))
    # equal times (sorted by time, then iteration): keep the last sample, the later iterate
    last = np.r_[lt[1:] != lt[:-1], True]
    lt, le = lt[last], le[last]
    out = np.interp(lg, lt, le, left=np.nan, right=le[-1])
    out[lg < lt[0] - 1e-12] = np.nan
    return out


def median_curve(curves: list[Curve], *, quantiles: tuple[float, float] = (0.25, 0.75), n_grid: int = 64,
                 floor: float = 1e-16) -> MedianCurve:
    """Median and quantile band of ``curves`` on a common log-time grid (see the module docstring)."""
    if not curves:
        raise InputError("median_curve needs at least one curve")
    q_lo, q_hi = quantiles
    if not 0.0 <= q_lo <= 0.5 <= q_hi <= 1.0:
        raise InputError(f"quantiles must satisfy 0 <= low <= 0.5 <= high <= 1, got {quantiles}")
    if not 2 <= n_grid <= 10_000:
        raise InputError(f"n_grid must be in [2, 10000], got {n_grid}")
    t0 = min(float(np.maximum(c.time_s[0], 1e-300)) for c in curves)
    t1 = max(float(c.time_s[-1]) for c in curves)
    grid = np.geomspace(t0, max(t1, t0), n_grid) if t1 > t0 else np.array([t0, t0])
    lg = np.log10(grid)
    L = np.vstack([_on_grid(c, lg, floor) for c in curves])
    ok = ~np.isnan(L)
    n_def = ok.sum(axis=0)
    med = np.full(grid.size, np.nan)
    lo, hi = med.copy(), med.copy()
    cols = n_def > 0
    if cols.any():
        med[cols] = np.nanmedian(L[:, cols], axis=0)
        lo[cols], hi[cols] = np.nanquantile(L[:, cols], [q_lo, q_hi], axis=0)
    return MedianCurve(grid, 10.0 ** med, 10.0 ** lo, 10.0 ** hi, n_def, len(curves), (q_lo, q_hi))
