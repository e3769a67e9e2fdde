/* Pure helpers of the dashboard (no DOM, no data): numbers written as Python's format(v, ".{p}g"), and the
   median convergence curve of several runs with its quantile band (the definition of the static figures,
   dualfem/reports/_bench_curves.py). Defines window.DashLib in a page, or
   module.exports under node (tests/test_dashboard.py checks them there). */
"use strict";
(function (root) {
  const FLOOR_ERR = 1e-16;          // errors below are drawn at 1e-16 (as the bench report's figures)
  const QLO = 0.25, QHI = 0.75;     // the band of the curves: the interquartile range across runs
  const GRID = 64;                  // time points of a median curve (log-spaced over the curves' times)

  /* format(v, ".{p}g") of Python: "1e-06", "0.00126", "1.5e+03"; "n/a" for null or non-finite */
  function g(v, p) {
    if (v === null || v === undefined || !isFinite(v)) return "n/a";
    if (v === 0) return "0";
    const e = Math.floor(Math.log10(Math.abs(Number(v.toPrecision(p)))));
    if (e < -4 || e >= p) {
      const [m, x] = v.toExponential(p - 1).split("e");
      const mant = m.includes(".") ? m.replace(/\.?0+$/, "") : m;
      return `${mant}e${x[0]}${x.slice(1).padStart(2, "0")}`;
    }
    return String(Number(v.toPrecision(p)));
  }

  /* log10 error of curve c ({t: times [s], e: errors}, sorted by time then iteration) on the log10 times lg:
     linear in (log10 time, log10 error) between its samples (errors floored at FLOOR_ERR), NaN before its
     first sample, its last error after its last sample; of equal times the last sample counts. Samples
     without a finite error or with a negative time are left out. */
  function onGrid(c, lg) {
    const lt = [], le = [];
    for (let j = 0; j < c.t.length; j++) {
      const t = c.t[j], e = c.e[j];
      if (t === null || e === null || !isFinite(t) || t < 0 || !isFinite(e)) continue;
      const x = Math.log10(Math.max(t, 1e-300)), y = Math.log10(Math.max(e, FLOOR_ERR));
      if (lt.length && lt[lt.length - 1] === x) le[le.length - 1] = y;
      else { lt.push(x); le.push(y); }
    }
    let k = 0;
    return lg.map((x) => {
      if (!lt.length || x < lt[0]) return NaN;
      if (x >= lt[lt.length - 1]) return le[le.length - 1];
      while (lt[k + 1] <= x) k++;          // lg ascending: lt[k] <= x < lt[k + 1]
      return le[k] + (le[k + 1] - le[k]) * (x - lt[k]) / (lt[k + 1] - lt[k]);
    });
  }

  /* The q-quantile of ascending values, linear between order statistics (numpy's default). */
  function quantile(sorted, q) {
    const pos = (sorted.length - 1) * q, lo = Math.floor(pos), hi = Math.ceil(pos);
    return lo === hi ? sorted[lo] : sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo);
  }

  /* Median and [QLO, QHI] band across curves, as the static figures draw them
     (dualfem.reports._bench_curves.median_curve): GRID log-spaced times from the earliest first sample to
     the latest last sample; at each time the quantiles of log10 error over the curves started by then (a
     geometric band). {t, med, lo, hi, n} (n: curves started; null where none), or null without a sample. */
  function medianBand(curves) {
    const kept = curves.map((c) => {
      const idx = c.t.map((t, j) => j).filter((j) => c.t[j] !== null && isFinite(c.t[j]) && c.t[j] >= 0 &&
                                                   c.e[j] !== null && isFinite(c.e[j]));
      return { t: idx.map((j) => c.t[j]), e: idx.map((j) => c.e[j]) };
    }).filter((c) => c.t.length);
    if (!kept.length) return null;
    const t0 = Math.min(...kept.map((c) => Math.max(c.t[0], 1e-300)));
    const t1 = Math.max(t0, ...kept.map((c) => c.t[c.t.length - 1]));
    const grid = [];
    if (t1 > t0) {
      for (let j = 0; j < GRID; j++) grid.push(t0 * Math.pow(t1 / t0, j / (GRID - 1)));
      grid[0] = t0; grid[GRID - 1] = t1;
    } else grid.push(t0, t0);
    const lg = grid.map((t) => Math.log10(t));
    const L = kept.map((c) => onGrid(c, lg));
    const med = [], lo = [], hi = [], n = [];
    lg.forEach((x, i) => {
      const v = L.map((row) => row[i]).filter((y) => !Number.isNaN(y)).sort((a, b) => a - b);
      n.push(v.length);
      const q = (p) => v.length ? Math.pow(10, quantile(v, p)) : null;
      med.push(q(0.5)); lo.push(q(QLO)); hi.push(q(QHI));
    });
    return { t: grid, med, lo, hi, n };
  }

  const lib = { g, onGrid, quantile, medianBand, FLOOR_ERR, QLO, QHI, GRID };
  if (typeof module !== "undefined" && module.exports) module.exports = lib;
  else root.DashLib = lib;
})(typeof window !== "undefined" ? window : this);
