/* Pure helpers of the dashboard (no DOM, no data): numbers written as Python's format(v, ".{p}g"), and the
   median convergence curve of several runs with its quantile band. Defines window.DashLib in a page, or
   module.exports under node (tests/test_dashboard.py checks them there). */
"use strict";
(function (root) {
  const FLOOR_ERR = 1e-16;          // errors below are drawn at 1e-16 (as the bench report's figures)
  const QLO = 0.25, QHI = 0.75;     // the band of the curves: the interquartile range across runs
  const GRID = 60;                  // time points of a median curve (log-spaced over the curves' times)

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

  /* The error of curve c ({t: times [s], e: errors}) at time t: that of its last sample at or before t with
     an error (at least FLOOR_ERR), so a finished run keeps its last error; +Infinity before its first sample. */
  function valueAt(c, t) {
    let v = Infinity;
    for (let j = 0; j < c.t.length && c.t[j] <= t * (1 + 1e-12); j++) {
      if (c.e[j] !== null && isFinite(c.e[j])) v = Math.max(c.e[j], FLOOR_ERR);
    }
    return v;
  }

  /* The q-quantile of ascending values (linear interpolation, as numpy's default); null when it is not
     finite (more than a (1 - q) share of the curves has not started yet). */
  function quantile(sorted, q) {
    const pos = (sorted.length - 1) * q, lo = Math.floor(pos), hi = Math.ceil(pos);
    const v = lo === hi ? sorted[lo] : sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo);
    return isFinite(v) ? v : null;
  }

  /* Median and [QLO, QHI] quantiles across curves, on GRID log-spaced times from the earliest to the latest
     positive sample time: {t, med, lo, hi} (null where undefined), or null without a positive time. */
  function medianBand(curves) {
    let tmin = Infinity, tmax = 0;
    for (const c of curves) for (const t of c.t) if (t > 0) { tmin = Math.min(tmin, t); tmax = Math.max(tmax, t); }
    if (!(tmax > 0)) return null;
    const grid = [];
    for (let j = 0; j < GRID; j++) grid.push(tmin === tmax ? tmin : tmin * Math.pow(tmax / tmin, j / (GRID - 1)));
    const med = [], lo = [], hi = [];
    for (const t of grid) {
      const vals = curves.map((c) => valueAt(c, t)).sort((a, b) => a - b);
      med.push(quantile(vals, 0.5)); lo.push(quantile(vals, QLO)); hi.push(quantile(vals, QHI));
    }
    return { t: grid, med, lo, hi };
  }

  const lib = { g, valueAt, quantile, medianBand, FLOOR_ERR, QLO, QHI, GRID };
  if (typeof module !== "undefined" && module.exports) module.exports = lib;
  else root.DashLib = lib;
})(typeof window !== "undefined" ? window : this);
