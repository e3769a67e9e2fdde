"""Penalty with regularized friction: the frictional part of ``solvers/penalty.py``.

For a penalty parameter rho (stress / length) minimise, with no constraint,

    P_rho(x) = 1/2 x'Kx - F'x + sum_normal w rho/2 ((-[x_nu])^+)^2 + sum_nodes w h_rho(s_j),
    h_rho(s) = rho/2 ||s||^2 if rho ||s|| <= g, else g ||s|| - g^2 / (2 rho)     (Huber: the smooth approximation
                                                                                of Tresca's g ||s||),

which is the frictional modified Lagrangian of :mod:`dualfem.numerics.friction_spaces` at zero multipliers with
r = rho, so the same generalized Newton + Armijo minimises it (:func:`dualfem.numerics.friction_uzawa.inner`).
The multipliers are the penalty forces ``w P(-rho Gs x)`` (``K x - F = Gs' mu`` holds at the minimiser
exactly): normal ``rho w (-[x_nu])^+``, friction ``-w g s/||s||`` on slipping nodes (exact) and ``-rho w s`` on
sticking ones. The method's intrinsic errors are the penetration ``mu_n / (rho w)`` and the creep of sticking
nodes ``||mu_t|| / (rho w)``; rho grows by ``rho_growth`` (warm-started Newton each time) until both are at
most ``tol`` relative to ``max |x_I|`` (the load's length as a floor), or rho reaches ``rho_max_factor`` x rho0:
then ``inaccurate``. The threshold g is the block's (Tresca) or read from the current penalty pressure (a
Coulomb block: used only through :func:`dualfem.numerics.coulomb.coulomb_fixed_point`, one Tresca problem at a
time, by the plugin).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from dualfem.numerics.coulomb import coulomb_fixed_point
from dualfem.numerics.friction_spaces import Layout, project
from dualfem.numerics.friction_uzawa import inner


@dataclass
class PenaltyRun:
    """The end of :func:`continuation`: ``z`` (the space's unknowns), ``mu`` (penalty forces, stacked),
    ``status``, ``message``, ``newton`` steps, ``stages``, final ``rho``, ``error`` (the larger of penetration and
    creep, length) and ``history`` (per stage)."""

    z: np.ndarray
    mu: np.ndarray
    status: str
    message: str
    newton: int
    stages: int
    rho: float
    error: float
    history: list = field(default_factory=list)


def errors(lay: Layout, s: np.ndarray, g: list[np.ndarray], rho: float) -> float:
    """The larger of the penetration ``max (-[x_nu])^+`` and the creep ``max ||s_j||`` of sticking nodes (length),
    from the stacked gaps ``s = Gs x``."""
    err = float(np.maximum(-s[lay.normal], 0.0).max(initial=0.0))
    for j in range(len(lay.fric)):
        n = np.linalg.norm(lay.nodes(s, j), axis=1)
        stick = rho * n <= g[j]
        err = max(err, float(n[stick].max(initial=0.0)))
    return err


def polish(space, lay: Layout, z: np.ndarray, g: list[np.ndarray], rho: float, rho_new: float | None = None):
    """(z, mu) recomputed stably on the piece of ``z`` at ``rho`` (penalised normal rows and sticking nodes as
    springs, slipping nodes at their exact forces ``-w g s/||s||``), the springs' stiffness ``rho_new w``
    (default rho), or None when the polished point leaves that piece (then the Newton iterate's forces stand).
    With ``rho_new`` > rho it is the predictor of the next continuation stage: the stuck nodes' creep shrinks by
    rho / rho_new with the forces kept, where a plain warm start would see every stuck node slip (rho_new ||s||
    > g) and the semismooth Newton would crawl back to stick with tiny Armijo steps."""
    s = space.G @ z
    A = lay.normal & (s < 0)
    fixed = np.zeros(lay.m)
    for j in range(len(lay.fric)):
        sj, n = lay.nodes(s, j), np.linalg.norm(lay.nodes(s, j), axis=1)
        stick = rho * n <= g[j]
        lay.nodes(A, j)[stick] = True
        slip = ~stick
        lay.nodes(fixed, j)[slip] = -(lay.nodes(lay.w, j)[slip] * (g[j][slip] / n[slip])[:, None]) * sj[slip]
    out = space.polish(A, (rho if rho_new is None else rho_new) * lay.w[A], fixed)
    if out is None:
        return None
    zp, mu = out
    sp_ = space.G @ zp
    if np.any(mu[A & lay.normal] < 0) or np.any(sp_[lay.normal & ~A] < 0):
        return None
    for j in range(len(lay.fric)):
        stick = lay.nodes(A, j)[:, 0]
        if np.any(np.linalg.norm(lay.nodes(mu, j)[stick], axis=1) > lay.nodes(lay.w, j)[stick, 0] * g[j][stick]):
            return None
    return zp, mu


def continuation(space, lay: Layout, p: dict, rho0: float, length: float, floor2: float, local=None,
                 z0=None, rho_start: float | None = None) -> PenaltyRun:
    """The rho-continuation of the module docstring (``p``: the penalty plugin's parameters; ``local``: the
    indices of the defect unknowns in the space's vector, None for all; ``z0``: a warm start, ``rho_start`` the
    rho to start from (a warm start's final rho: the Coulomb fixed point's next Tresca solve), default rho0)."""
    deadline = time.perf_counter() + p["time_limit"]
    q = {"max_inner": p["max_iter"], "max_backtracks": p["max_backtracks"], "armijo_c": p["sigma"],
         "step_factor": 2.0, "tol_inner": p["newton_tol"]}
    z = space.start() if z0 is None else np.array(z0, float)
    y0 = np.zeros(lay.m)
    g = lay.bounds(y0)
    rho, rho_max = (rho0 if rho_start is None else rho_start), rho0 * p["rho_max_factor"]
    newton, stage, history = 0, 0, []
    while True:
        stage += 1
        z, steps, ok, msg = inner(space, lay, z, y0, g, rho, q, floor2, deadline)
        newton += len(steps)
        s = space.G @ z
        mu = lay.w * project(lay, -rho * s, g)
        pol = polish(space, lay, z, g, rho) if ok else None
        if pol is not None:
            z, mu = pol
            s = space.G @ z
        err = errors(lay, s, g, rho)
        xs = max(float(np.abs(z if local is None else z[local]).max(initial=0.0)), length, 1e-300)
        history.append({"stage": stage, "rho": rho, "newton": len(steps), "error": err / xs})
        if not ok:
            status = "time_limit" if time.perf_counter() > deadline else "max_iter"
            return PenaltyRun(z, mu, status, f"Newton did not converge at rho = {rho:.3g}: {msg}", newton, stage,
                              rho, err, history)
        if err <= p["tol"] * xs:
            return PenaltyRun(z, mu, "solved", f"penetration / creep {err / xs:.1e} relative at rho = {rho:.3g}",
                              newton, stage, rho, err, history)
        if rho * p["rho_growth"] > rho_max * (1 + 1e-12):
            return PenaltyRun(z, mu, "inaccurate", f"rho reached its cap {rho:.3g} with penetration / creep "
                              f"{err / xs:.1e} relative > tol {p['tol']:g}", newton, stage, rho, err, history)
        pred = polish(space, lay, z, g, rho, rho * p["rho_growth"])
        if pred is not None:
            z = pred[0]
        rho *= p["rho_growth"]


@dataclass
class PenaltyAnswer:
    """What :func:`solve_friction` hands the plugin: the answer on all unknowns and its report."""

    status: str
    x: np.ndarray
    mu: np.ndarray
    message: str
    iterations: dict
    history: list
    info: dict


class _TrescaFailed(Exception):
    """A Tresca solve inside the Coulomb fixed point ended without ``solved`` (its PenaltyRun in args[0])."""


def solve_friction(qp, space, lay: Layout, p: dict, rho0: float, length: float, floor2: float,
                   local=None) -> PenaltyAnswer:
    """The penalty plugin's frictional solve: one continuation (Tresca), or the Coulomb fixed point over Tresca
    continuations (:func:`dualfem.numerics.coulomb.coulomb_fixed_point`; each warm started at the previous x,
    and at its final rho when the threshold moved by < 10 %: after a jump such as g = 0 -> mu_f lambda every
    stuck node would look slipping at that rho, so the continuation starts from rho0 again)."""
    runs: list[PenaltyRun] = []

    def solve(lay_k, z0=None, rho=None) -> PenaltyRun:
        runs.append(continuation(space, lay_k, p, rho0, length, floor2, local, z0, rho))
        return runs[-1]

    extra: dict = {}
    details: dict = {}
    if not lay.coulomb():
        out = solve(lay)
        status, x, mu, msg = out.status, space.full(out.z), out.mu, out.message
    else:
        bounds: list = []

        def solve_tresca(qt, warm):
            lay_t = Layout(qt)
            g = np.concatenate(lay_t.bounds(np.zeros(lay_t.m)))
            near = bool(bounds) and np.abs(g - bounds[-1]).max(initial=0.0) < 0.1 * np.abs(g).max(initial=0.0)
            bounds.append(g)
            out = solve(lay_t, *((None, None) if warm is None else (runs[-1].z, runs[-1].rho if near else None)))
            if out.status != "solved":
                raise _TrescaFailed(out)
            return space.full(out.z), out.mu, {}

        try:
            res = coulomb_fixed_point(qp, solve_tresca, tol=max(100 * p["tol"], 1e-8),
                                      max_iter=int(p["coulomb_max_iter"]))
            status, x, mu, extra, details = res.status, res.x, res.mu, res.summary(), res.details()
            msg = runs[-1].message if res.status == "solved" else \
                f"Coulomb fixed point {'stalled' if res.stalled else 'hit coulomb_max_iter'}"
        except _TrescaFailed as exc:
            out = exc.args[0]
            status, x, mu = out.status, space.full(out.z), out.mu
            msg = f"Tresca solve {len(runs)} of the Coulomb fixed point: {out.message}"
    last = runs[-1]
    return PenaltyAnswer(status, x, mu, msg,
                         {"newton": sum(r.newton for r in runs), "continuation": sum(r.stages for r in runs), **extra},
                         [h for r in runs for h in r.history],
                         {"rho": last.rho, "penetration": last.error, "tresca_solves": len(runs), **details})
