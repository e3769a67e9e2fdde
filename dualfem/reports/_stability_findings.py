"""The "What sets the boundaries" paragraphs of ``dualfem report stability``: each explanation is
stated only when the stress runs show the effect it explains."""
from __future__ import annotations

from dualfem.experiments.stress_grid import r_set_by_user


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _findings(recs) -> list[str]:
    """Explanations of the boundaries, each stated only when the data show the effect."""
    import numpy as np


    out = []
    # the explanation below is about an outer (dual) stopping test: only runs that have one
    wrong1 = [r for r in recs if r["grade"] == "silent_wrong" and r.get("main_iterations") == 1
              and "outer" in (r.get("iterations") or {})]
    if wrong1:
        prods = sorted({r["coords"]["r"] * r["coords"]["delta"] for r in wrong1 if "r" in r["coords"]
                        and isinstance(r["coords"]["r"], float)})
        out.append(f"- **Silent wrong answers after one iteration** ({len(wrong1)} runs: "
                   + ", ".join(sorted({r['solver'] for r in wrong1}))
                   + (f"; r x delta = {', '.join(_fmt(p) for p in prods)}" if prods else "")
                   + "). These runs stopped after the first outer iteration with status solved. The outer stopping "
                   "test is an absolute bound on the change of the dual variable (max_j |l_j^(k+1) - l_j^k| <= "
                   "tol_outer); when r x delta is tiny the first update r [u_nu] is already below it, so 'no "
                   "progress' passes as 'converged'. The evaluator's KKT residuals do not catch it either: at "
                   "delta = 1e-12 the interface term dominates K and the scaled stationarity residual stays small "
                   "while the contact forces are wrong.")
    # the interface-dominated regime: delta <= 1e-6 (interface stiffness >> elastic stiffness)
    # runs that ended by meeting their own outer test (solved, or inaccurate after a rate check)
    rr = [r for r in recs if r["axis"] == "r" and r.get("status") in ("solved", "inaccurate")
          and (r.get("main_iterations") or 0) > 1
          and r["coords"]["r"] * r["coords"]["delta"] <= 1.0 and r["coords"]["delta"] <= 1e-6
          and r_set_by_user(r.get("params_used") or {})]
    if len(rr) >= 3:
        x = np.log10([r["coords"]["r"] * r["coords"]["delta"] for r in rr])
        y = np.log10([r["main_iterations"] for r in rr])
        if np.ptp(x) > 0:
            slope = float(np.polyfit(x, y, 1)[0])
            pairs = ", ".join(f"{_fmt(a)}: {int(b)}" for a, b in
                              sorted((r["coords"]["r"] * r["coords"]["delta"], r["main_iterations"]) for r in rr))
            out.append(f"- **Uzawa at small delta**: for delta <= 1e-6 and r x delta <= 1 the outer iterations "
                       f"needed to meet the outer test behave like (r delta)^({slope:.2f}) (least-squares fit over "
                       f"{len(rr)} runs, {pairs}): the slowest dual "
                       "mode has a compliance ~ delta (the 1/delta interface term), so it contracts by about "
                       "1 / (1 + r delta) per outer iteration. The paper's r = 1e7 gives r delta = 1e-2 at delta = "
                       "1e-9 (its ~900 iterations); choosing r from delta (or from the dual compliance, as "
                       "`uzawa_auto` does) keeps r delta, and the iteration count, constant.")
    scaled_fail = [r for r in recs if r["axis"] in ("load", "units") and r.get("third_party")
                   and r["grade"] in HONEST_OR_WRONG and (r.get("params_used") or {}).get("scale") is True]
    if scaled_fail:
        out.append(f"- **Scaled third-party backends on the load and units axes** ({len(scaled_fail)} runs: "
                   + ", ".join(sorted({f"{r['solver']} ({_fmt(list(r['coords'].values())[0])})" for r in scaled_fail}))
                   + "). They receive the QP normalised by `dualfem.numerics.scaling`, which multiplies the objective "
                   "by c = 1 / max|D F|: the scaled Hessian c D K D then grows like 1 / (load magnitude) and the "
                   "unknowns shrink like the load, which Clarabel's absolute tolerances and OSQP's rho do not "
                   "follow. Measured remedy (not applied here, core code): scale the unknowns by the load "
                   "instead (x = s D y with s = max|D F|, P = D K D, q = -D F / s): in the side test "
                   "`python benchmarks/stress_scaling_check.py` (N = 16) both backends then solve every load "
                   "scale 1e-6..1e6 and every unit system to a relative error <= 1e-10.")
    # locking is an explanation only where nu is near 1/2 (lambda / mu >= 5, nu >= 0.4375)
    nu_fail = [r for r in recs if r["axis"] == "nu" and r["grade"] not in ("correct", "skipped", "unverified")
               and r["coords"]["nu"] >= 0.4375]
    if nu_fail:
        out.append(f"- **Near-incompressible** (nu -> 0.5): {len(nu_fail)} runs not correct ("
                   + ", ".join(sorted({f"{r['solver']} at nu = {_fmt(r['coords']['nu'])}" for r in nu_fail}))
                   + "); lambda / mu = 2 nu / (1 - 2 nu) reaches 5000 at nu = 0.4999.")
    return (["## What sets the boundaries", ""] + out + [""]) if out else []


HONEST_OR_WRONG = ("failed", "flagged", "timeout", "crashed", "silent_wrong")
