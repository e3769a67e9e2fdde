"""Coulomb friction as a fixed point over Tresca problems: g_j <- mu_f,j max(lambda_j, 0) / w_j.

Coulomb friction (:class:`dualfem.core.laws.Coulomb`) is a quasi-variational inequality: the radius of node
j's disc, ``mu_f,j max(lambda_j, 0)``, depends on the normal multiplier lambda_j of the answer itself. For a
given threshold g (stress units) the problem is a convex Tresca problem (:class:`dualfem.core.laws.Tresca`,
radius ``g_j w_j``); the classical scheme (Kushniruk & Namm 2009; Haslinger, Hlavacek & Necas) iterates

    g^0 = 0 (the frictionless problem) or from a warm start,   (x^k, mu^k) = Tresca(g^k),
    T(g^k)_j = mu_f,j max(lambda^k_j, 0) / w_j,   g^{k+1} = g^k + omega (T(g^k) - g^k),

(omega = 1: plain Picard; by default omega is halved, down to 1/16, whenever the change of g did not fall
below 0.9 x the previous change: where the map is not a contraction plain Picard can cycle between stick
and slip states around a solution, as on the coupled one-node spring of tests/test_coulomb_fixed_point.py;
a closed 2D crack at mu_f = 0.2 contracts by ~0.01 per step and keeps omega = 1) and stops when
``||T(g^k) - g^k||_inf <= tol ||T(g^k)||_inf`` (relative; an all-zero threshold, mu_f = 0, stops at once).
The answer is the last Tresca solve (x^k, mu^k); its friction radii are ``g^k w`` while its own normal
multipliers ask ``T(g^k) w``: the Coulomb condition holds to the relative change ``tol``.

**Signature.** ``coulomb_fixed_point(qp, solve_tresca, tol, max_iter, *, warm=None, stall=5, relax=None)`` where
``solve_tresca(qp_tresca, warm) -> (x, mu, counters)``: ``qp_tresca`` is ``qp`` with every Coulomb block's law
replaced by Tresca with the current threshold (same blocks, rows, weights and multiplier layout, so a warm start
carries over), ``warm`` None or the previous ``(x, mu)``, and ``counters`` a dict of the inner solve's
counters (numbers are summed over the fixed point; anything else is kept from the last solve). A solve that
cannot continue raises; the caller turns that into its own status.

**Limits.** The fixed point is a contraction, and the Coulomb problem's solution unique, only for small
coefficients (mu_f below a bound of order sqrt(1 - 2 nu)/(1 - nu) in 2D elasticity for the continuous
problem, mesh dependent for the discrete one); for larger mu_f several solutions may exist and the iteration
may cycle or drift. The code observes, it does not assume: each iteration's change of g and the ratio of
successive changes (the observed contraction factor) are reported; when the change has not decreased for
``stall`` consecutive iterations the loop stops with ``stalled`` True, and at ``max_iter`` it stops too:
both give status ``"max_iter"``, never ``"solved"`` (the last Tresca answer is still returned, for the
certificate to judge).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from dualfem.core.constraints import Constraint, split
from dualfem.core.errors import InputError
from dualfem.core.laws import Coulomb, Tresca
from dualfem.core.qp import QP

#: solve_tresca(qp_tresca, warm) -> (x, mu, counters); warm is None or the previous (x, mu)
TrescaSolve = Callable[[QP, "tuple[np.ndarray, np.ndarray] | None"], "tuple[np.ndarray, np.ndarray, dict]"]


@dataclass
class CoulombResult:
    """The answer of :func:`coulomb_fixed_point`: the last Tresca solve ``x``, ``mu`` (stacked multipliers of
    every block), ``status`` ``"solved"`` (converged to ``tol``) or ``"max_iter"`` (max_iter reached or stalled),
    ``iterations`` (Tresca solves), ``changes`` (per iteration, ||g^{k+1} - g^k||_inf / ||g^{k+1}||_inf),
    ``contractions`` (ratios of successive absolute changes: the observed contraction factor), ``stalled``,
    ``threshold`` (the g of the last solve, per Coulomb block, stress units), ``counters`` (the inner
    solves' counters: numbers summed) and ``relax`` (the relaxation omega at the end)."""

    x: np.ndarray
    mu: np.ndarray
    status: str
    iterations: int
    changes: list[float] = field(default_factory=list)
    contractions: list[float] = field(default_factory=list)
    stalled: bool = False
    threshold: tuple[np.ndarray, ...] = ()
    counters: dict = field(default_factory=dict)
    relax: float = 1.0

    def summary(self) -> dict:
        """Whole-number counters for a Solution's ``iterations`` dict (the runner keeps whole numbers only)."""
        return {"coulomb_iterations": self.iterations, "coulomb_stalled": int(self.stalled)}

    def details(self) -> dict:
        """The rest, for a Solution's ``info``: the largest observed contraction, the last relative change, the
        relaxation, and the per-iteration changes and contractions."""
        rho = [c for c in self.contractions if np.isfinite(c)]
        return {"coulomb_contraction": float(max(rho)) if rho else 0.0,
                "coulomb_change": float(self.changes[-1]) if self.changes else 0.0, "coulomb_relax": self.relax,
                "coulomb_changes": [float(c) for c in self.changes],
                "coulomb_contractions": [float(c) for c in self.contractions]}


def coulomb_blocks(qp: QP) -> list[int]:
    """Indices (into ``qp.constraints``: 0 is the Signorini block) of the blocks with a Coulomb law."""
    return [k for k, b in enumerate(qp.constraints) if isinstance(b.law, Coulomb)]


def _node_weights(block: Constraint) -> np.ndarray:
    return np.asarray(block.weights, float)[::getattr(block.law, "components", 1)]


def thresholds(qp: QP, mu: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per Coulomb block, the Tresca threshold g_j = mu_f,j max(lambda_j, 0) / w_j (stress units) that the
    multipliers ``mu`` (stacked, every block) ask for."""
    blocks = qp.constraints
    mus = tuple(split(blocks, np.asarray(mu, float)))
    out = []
    for k in coulomb_blocks(qp):
        b = blocks[k]
        law = b.law
        assert isinstance(law, Coulomb)
        out.append(law.radius(b.weights, mus) / _node_weights(b))
    return tuple(out)


def tresca_qp(qp: QP, g: tuple[np.ndarray, ...]) -> QP:
    """``qp`` with the law of its k-th Coulomb block replaced by Tresca with threshold ``g[k]`` (same G,
    weights and rows: the multiplier layout is unchanged)."""
    idx = coulomb_blocks(qp)
    if len(g) != len(idx):
        raise ValueError(f"{len(idx)} Coulomb blocks, {len(g)} thresholds")
    blocks = list(qp.blocks)
    for k, gk in zip(idx, g):
        b = blocks[k - 1]
        c = getattr(b.law, "components", 1)
        blocks[k - 1] = Constraint(b.G, b.weights, Tresca(np.asarray(gk, float), components=c))
    return dataclasses.replace(qp, blocks=tuple(blocks))


def _add(total: dict, counters: dict) -> None:
    for key, v in (counters or {}).items():
        if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool):
            total[key] = total.get(key, 0) + v
        else:
            total[key] = v


def _inf(g: tuple[np.ndarray, ...]) -> float:
    return max((float(np.abs(gk).max(initial=0.0)) for gk in g), default=0.0)


def coulomb_fixed_point(qp: QP, solve_tresca: TrescaSolve, tol: float = 1e-8, max_iter: int = 50, *,
                        warm: tuple[np.ndarray, np.ndarray] | None = None, stall: int = 5,
                        relax: float | None = None) -> CoulombResult:
    """Solve the Coulomb-frictional ``qp`` by Tresca solves (see the module docstring for the contract).

    ``warm``: a previous ``(x, mu)`` of the same QP layout: the first threshold is read from its mu and the
    first Tresca solve is warm started from it (no frictionless solve); None: start from g = 0, the
    frictionless answer. ``tol``: relative change of the threshold (inf-norm) that stops; ``max_iter``: most
    Tresca solves; ``stall``: iterations without a decrease of the change that count as stalled; ``relax``:
    the relaxation omega of ``g <- g + omega (T(g) - g)`` (1: plain Picard); None: adaptive, from 1, halved
    (down to 1/16) after every iteration whose change did not fall below 0.9 x the previous one."""
    if not coulomb_blocks(qp):
        raise InputError(f"QP {qp.name!r} has no Coulomb block: the fixed point has nothing to iterate")
    if not (tol > 0 and max_iter >= 1 and stall >= 1 and (relax is None or 0 < relax <= 1)):
        raise InputError(f"coulomb_fixed_point: tol must be > 0, max_iter and stall >= 1, relax in (0, 1] "
                         f"(got {tol}, {max_iter}, {stall}, {relax})")
    if warm is None:
        g = tuple(np.zeros(_node_weights(qp.constraints[k]).size) for k in coulomb_blocks(qp))
    else:
        g = thresholds(qp, warm[1])
    omega = 1.0 if relax is None else float(relax)
    total: dict = {}
    changes: list[float] = []
    contractions: list[float] = []
    prev_abs, best, since_best = np.inf, np.inf, 0
    x = mu = None
    for it in range(1, max_iter + 1):
        x, mu, counters = solve_tresca(tresca_qp(qp, g), warm)
        _add(total, counters)
        warm = (x, mu)
        g_new = thresholds(qp, mu)
        diff = _inf(tuple(a - b for a, b in zip(g_new, g)))
        scale = _inf(g_new)
        changes.append(diff / scale if scale > 0 else 0.0 if diff == 0 else np.inf)
        if np.isfinite(prev_abs) and prev_abs > 0:
            contractions.append(diff / prev_abs)
        if diff <= tol * scale:
            return CoulombResult(x, mu, "solved", it, changes, contractions, False, g, total, omega)
        if relax is None and diff >= 0.9 * prev_abs:
            omega = max(omega / 2, 1.0 / 16)
        prev_abs = diff
        if diff < best:
            best, since_best = diff, 0
        else:
            since_best += 1
        if since_best >= stall or it == max_iter:
            return CoulombResult(x, mu, "max_iter", it, changes, contractions, since_best >= stall, g, total, omega)
        g = tuple(a + omega * (b - a) for a, b in zip(g, g_new))
    raise AssertionError("unreachable")       # the loop returns at it == max_iter
