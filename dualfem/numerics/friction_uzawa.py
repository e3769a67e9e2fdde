"""Uzawa on the frictional modified Lagrangian (the school's scheme: Vikhtenko & Namm 2007; Kushniruk & Namm
2009) with the paper's generalized Newton-Armijo inner loop: the friction part of ``solvers/uzawa.py``.

Outer iteration k (dual state y: normal pressures l and tangential tractions t, stresses; thresholds g):

    g^k = the friction blocks' thresholds at y^k (Tresca: fixed; Coulomb: mu_f max(l^k, 0) w_n / w_t, the
          threshold from the current pressure, the school's way),
    x^{k+1} = argmin_x M(x, y^k; g^k)          (generalized Newton + Armijo; the functional, its gradient and
                                                 Hessian: :mod:`dualfem.numerics.friction_spaces`),
    y^{k+1} = P_g^k(y^k - r Gs x^{k+1})        (normal rows onto l >= 0, friction nodes onto their discs),

stopping when ``max |y^{k+1} - y^k| <= tol max |y^{k+1}|`` (``tol_mode="relative"``; ``"absolute"``: tol in stress
units) and the remaining error estimate ``max(change rho / (1 - rho), change / (r mu_min))`` is within tol too
(the frictionless solver's honest stop; for Tresca the dual is concave and the bound that of the proximal
point method, for Coulomb, a quasi-variational problem, it is a heuristic). A convex Tresca problem converges
for every r > 0; Coulomb in the loop converges when the Coulomb problem's fixed point contracts (small mu_f).
Statuses: ``solved``, ``inaccurate`` (test met, error estimate above ``error_factor`` x tol, or the last inner
loop failed), ``max_iter``, ``stagnation``, ``time_limit``, ``numerical_error``: never ``solved`` unmet.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from dualfem.numerics.friction_spaces import Layout, newton_terms, project, remainder
from dualfem.numerics.newton_spaces import armijo_step


@dataclass
class FrictionRun:
    """The end of :func:`outer`: iterate ``z`` (the space's unknowns), dual state ``y`` (stresses: multipliers are
    ``w y``), ``status`` (a Status value), ``message``, outer ``k`` and summed inner ``m`` steps, ``history``."""

    z: np.ndarray
    y: np.ndarray
    status: str
    message: str
    k: int
    m: int
    history: list = field(default_factory=list)


def inner(space, lay: Layout, z, y, g, r: float, p: dict, floor2: float, deadline: float):
    """Generalized Newton-Armijo for min_x M(x, y; g); returns (z, step sizes, converged, message)."""
    G, w = space.G, lay.w
    steps: list[float] = []
    for _ in range(int(p["max_inner"])):
        a = y - r * (G @ z)
        grad = space.qgrad(z) - G.T @ (w * project(lay, a, g))
        coef, rot = newton_terms(lay, a, g, r)
        d = space.newton(coef, rot, grad)
        Gd, dQd, rGd = float(grad @ d), space.qform(d), r * (G @ d)
        s = 1.0
        if Gd > 0:
            s = armijo_step(Gd, dQd, lambda t, a=a, rGd=rGd: remainder(lay, a, t * rGd, g), w, r, p)
            if s is None:
                return z, steps, False, "Armijo backtracking failed"
        z = z - s * d
        steps.append(s)
        nz2 = space.norm2(z)
        if not np.isfinite(nz2):
            return z, steps, False, "NaN/inf"
        ratio = s * np.sqrt(max(dQd, 0.0)) / np.sqrt(max(nz2, floor2, 1e-300))
        if ratio < p["tol_inner"]:
            return z, steps, True, ""
        if time.perf_counter() > deadline:
            return z, steps, False, "time limit"
    return z, steps, False, f"max_inner={p['max_inner']} Newton steps without meeting tol_inner"


def _rate(history: list[dict], last: int = 5) -> float:
    ch = [h["dual_change"] for h in history[-(last + 1):]]
    if len(ch) < 3 or min(ch) <= 0:
        return 0.0
    return float(np.exp(np.mean(np.diff(np.log(ch)))))


def outer(space, lay: Layout, p: dict, r: float, mu_min, floor2: float, *, z0=None, y0=None,
          report=None) -> FrictionRun:
    """The outer Uzawa loop (module docstring). ``mu_min``: a callable returning the smallest dual compliance
    (for the honest stop; called once, when first needed); ``z0``/``y0`` a warm start (default K^-1 F and
    ``l0`` on the normal rows, 0 tractions); ``report(k, z, y)`` is called after every outer iteration."""
    deadline = time.perf_counter() + p["time_limit"]
    z = space.start() if z0 is None else np.array(z0, float)
    y = np.where(lay.normal, float(p["l0"]), 0.0) if y0 is None else np.array(y0, float)
    k = m = 0
    history: list[dict] = []
    best, best_k, mu = np.inf, 0, None
    change = np.inf
    while k < p["max_iter"]:
        g = lay.bounds(y)
        z, steps, ok, msg = inner(space, lay, z, y, g, r, p, floor2, deadline)
        m += len(steps)
        if not np.all(np.isfinite(z)):
            return FrictionRun(z, y, "numerical_error", "NaN/inf in the Newton iterate", k, m, history)
        y_new = project(lay, y - r * (space.G @ z), g)
        change = float(np.abs(y_new - y).max(initial=0.0))
        k += 1
        history.append({"k": k, "dual_change": change, "inner_steps": len(steps), "inner_converged": ok,
                        "active": int(np.count_nonzero(y_new[lay.normal] > 0))})
        y = y_new
        if report is not None:
            report(k, z, y)
        if not np.isfinite(change):
            return FrictionRun(z, y, "numerical_error", "NaN/inf in the multiplier update", k, m, history)
        tol = p["tol"] * (1.0 if p["tol_mode"] == "absolute" else max(np.abs(y).max(initial=0.0), 1e-300))
        if change <= tol:
            if not ok:
                return FrictionRun(z, y, "inaccurate", f"outer test met but last inner loop failed: {msg}", k, m,
                                   history)
            rho = _rate(history)
            mu = mu_min() if mu is None else mu
            est = max(change * rho / (1.0 - rho) if rho < 1 else np.inf, change / (r * max(mu, 1e-300)))
            history[-1]["dual_error_estimate"] = est
            if est <= tol:
                return FrictionRun(z, y, "solved", "", k, m, history)
            if p["tol_mode"] == "absolute" and est > p["error_factor"] * tol:
                return FrictionRun(z, y, "inaccurate", f"outer test met, but the estimated multiplier error "
                                   f"{est:.2g} > {p['error_factor']:g} x tol (observed rate {rho:.4f})", k, m, history)
            if p["tol_mode"] == "absolute":
                return FrictionRun(z, y, "solved", "", k, m, history)
        if change < best:
            best, best_k = change, k
        elif k - best_k >= p["stall_window"]:
            return FrictionRun(z, y, "stagnation", f"dual change has not improved on {best:.3g} for "
                               f"{p['stall_window']} outer iterations", k, m, history)
        if time.perf_counter() > deadline:
            return FrictionRun(z, y, "time_limit", f"time limit {p['time_limit']} s reached", k, m, history)
    return FrictionRun(z, y, "max_iter", f"max_iter={p['max_iter']} reached; last dual change {change:.3g}", k, m,
                       history)
