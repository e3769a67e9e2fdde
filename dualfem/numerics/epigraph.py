"""A QP with Tresca friction blocks as a conic program over ``z = [y, t]``: what the conic and QP backends solve.

Tresca friction (:class:`dualfem.core.laws.Tresca`) adds ``sum_j r_j ||s_j||`` to the objective (``s_j`` the c
tangential jumps of friction node j, ``r_j`` its radius, a force: :meth:`dualfem.core.laws.Law.norm_term`).
With one epigraph variable ``t_j >= ||s_j||`` per friction node the problem becomes

    minimize 1/2 y'P y + q'y + sum_j rt_j t_j   subject to   A z in K,

on the normalised unknowns of :mod:`dualfem.numerics.scaling` (``x = c D y``; the rows of one friction node
share one scale factor, since a norm is not invariant under scaling its components apart). The rows of A, in
block order:

* a block whose law has a cone (:meth:`dualfem.core.laws.Law.conic`): its rows ``G_b y`` in that cone;
* a Tresca block, ``soc`` (3D discs, or 2D on request): per node the second-order cone
  ``(t_j, s_j) in {||s|| <= t}`` (``1 + c`` rows);
* a Tresca block in 2D, linear (a box: what a QP backend takes): ``t_j - s_j >= 0`` for all nodes, then
  ``t_j + s_j >= 0`` (``2 p`` nonneg rows).

Duals: ``lam`` with ``P z + q = A' lam`` (``lam`` in the dual cone; Clarabel's ``z`` for its ``A_cl = -A``, OSQP's
``-y``). The blocks' scaled multipliers follow (:meth:`Epigraph.multipliers`): a cone block's rows as they are,
a Tresca node's ``nu_j = lam_s`` (soc: the cone's s part) or ``lam_2 - lam_1`` (linear), and then
``mu = c R nu`` (``K x - F = G' mu``, the sign of the QP). A block with neither a cone nor a norm term (Coulomb)
cannot be written here: InputError (a solver that lists the law takes it another way, or is skipped).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from dualfem.core.constraints import offsets
from dualfem.core.errors import InputError
from dualfem.core.qp import QP
from dualfem.numerics.scaling import ScaledQP, scale

#: cone kinds of an :class:`Epigraph` (a backend maps them to its own types)
KINDS = ("nonneg", "zero", "soc")


@dataclass
class NormBlock:
    """A block whose law adds ``sum_j r_j ||s_j||``: its stacked rows ``rows``, components ``c`` per node and
    the scaled radii ``rt`` (per node; the objective's coefficients of t)."""

    rows: np.ndarray
    c: int
    rt: np.ndarray


@dataclass
class Epigraph:
    """The conic program of the module docstring: ``P``, ``q`` over ``z = [y (n), t (p)]``, ``A`` (rows of
    ``cones``, each ``(kind, size)``), the scaling ``scaled`` (uniform per friction node) and how each block's
    rows sit in A (``layout``: per block ``("cone", start)``, ``("soc", start)`` or ``("linear", start)``)."""

    P: sp.csc_matrix
    q: np.ndarray
    A: sp.csr_matrix
    cones: list[tuple[str, int]]
    scaled: ScaledQP
    n: int
    layout: list[tuple[str, int, int]]
    norms: list[NormBlock]

    def multipliers(self, lam: np.ndarray) -> np.ndarray:
        """The blocks' scaled multipliers ``nu`` (stacked, length m_total) from the duals ``lam`` of ``A z in K``."""
        lam = np.asarray(lam, float)
        nu, norms = [], iter(self.norms)
        for form, start, m in self.layout:
            if form == "cone":
                nu.append(lam[start:start + m])
            elif form == "soc":
                c = next(norms).c
                nu.append(lam[start:start + (c + 1) * (m // c)].reshape(-1, c + 1)[:, 1:].ravel())
            else:
                next(norms)
                nu.append(lam[start + m:start + 2 * m] - lam[start:start + m])
        return np.concatenate(nu) if nu else np.zeros(0)

    def unscale(self, z: np.ndarray, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x, mu) of the QP from the backend's primal ``z`` and duals ``lam``."""
        return self.scaled.unscale(np.asarray(z, float)[:self.n], self.multipliers(lam))


def norm_blocks(qp: QP) -> list[int]:
    """Indices (into ``qp.constraints``) of the blocks whose law is a norm term of the objective."""
    return [k for k, b in enumerate(qp.constraints) if b.law.norm_term(b.weights) is not None]


def not_linear(qp: QP) -> str | None:
    """Why ``qp`` is not a QP for a QP backend (None when it is): its friction blocks in 3D (Tresca, or Coulomb's
    Tresca problems) are discs, second-order cones that no linear row describes."""
    for k, b in enumerate(qp.constraints):
        if getattr(b.law, "components", 1) > 1:
            return (f"constraint block {k} ({b.law.name}) holds 3D friction discs (second-order cones), which a QP "
                    f"backend cannot take; 2D friction (intervals) only")
    return None


def uniform_scaling(qp: QP, enable: bool = True) -> ScaledQP:
    """:func:`dualfem.numerics.scaling.scale` with the rows of each friction node scaled by one factor (the
    smallest of its rows' factors: every scaled row of the node then has infinity norm <= 1)."""
    s = scale(qp, enable)
    if not enable:
        return s
    o = offsets(qp.constraints)
    r = s.r.copy()
    for k in norm_blocks(qp):
        c = qp.constraints[k].law.components
        node = r[o[k]:o[k + 1]].reshape(-1, c).min(axis=1)
        r[o[k]:o[k + 1]] = np.repeat(node, c)
    A = (sp.diags(r / s.r) @ s.A).tocsr()
    return ScaledQP(s.P, s.q, A, s.d, r, s.c)


def epigraph(qp: QP, enable_scale: bool = True, soc_2d: bool = False) -> Epigraph:
    """The conic program of ``qp`` (module docstring); 2D friction as linear rows unless ``soc_2d``."""
    s = uniform_scaling(qp, enable_scale)
    o = offsets(qp.constraints)
    n = qp.n
    p_total = sum(qp.constraints[k].m // qp.constraints[k].law.components for k in norm_blocks(qp))
    blocks, cones, layout, norms, rts = [], [], [], [], []
    row, p = 0, 0
    for k, b in enumerate(qp.constraints):
        Gs = s.A[o[k]:o[k + 1]]
        radius = b.law.norm_term(b.weights)
        if radius is None:
            kind = b.law.conic()
            if kind not in ("nonneg", "zero"):
                raise InputError(f"the {b.law.name!r} law of constraint block {k} is neither a cone nor a norm term "
                                 f"of the objective: it cannot be written as a conic program")
            blocks.append((Gs, None))
            cones.append((kind, b.m))
            layout.append(("cone", row, b.m))
            row += b.m
            continue
        c = b.law.components
        nodes = b.m // c
        rt = np.asarray(radius, float) / (s.c * s.r[o[k]:o[k + 1]:c])
        T = sp.csr_matrix((np.ones(nodes), (np.arange(nodes), p + np.arange(nodes))), shape=(nodes, p_total))
        norms.append(NormBlock(np.arange(o[k], o[k + 1]), c, rt))
        if c == 1 and not soc_2d:
            blocks.append((sp.vstack([-Gs, Gs]), sp.vstack([T, T])))
            cones.append(("nonneg", 2 * nodes))
            layout.append(("linear", row, nodes))
            row += 2 * nodes
        else:
            blocks.append((_interleave(Gs, c), _interleave_t(T, c)))
            cones.extend([("soc", c + 1)] * nodes)
            layout.append(("soc", row, b.m))
            row += b.m + nodes
        rts.append(rt)
        p += nodes
    A = sp.vstack([sp.hstack([Gy, sp.csr_matrix((Gy.shape[0], p)) if Gt is None else Gt]) for Gy, Gt in blocks],
                  format="csr")
    P = sp.block_diag([s.P, sp.csr_matrix((p, p))], format="csc")
    q = np.concatenate([s.q, *rts]) if rts else s.q.copy()
    return Epigraph(P, q, A, cones, s, n, layout, norms)


def _interleave(Gs: sp.csr_matrix, c: int) -> sp.csr_matrix:
    """Per node j: an empty row (its t_j), then its c rows of ``Gs``."""
    nodes = Gs.shape[0] // c
    perm = np.arange(Gs.shape[0]) + np.repeat(np.arange(1, nodes + 1), c)
    out = sp.coo_matrix(Gs)
    return sp.csr_matrix((out.data, (perm[out.row], out.col)), shape=(Gs.shape[0] + nodes, Gs.shape[1]))


def _interleave_t(T: sp.csr_matrix, c: int) -> sp.csr_matrix:
    """Per node j: the row of t_j, then c empty rows."""
    out = sp.coo_matrix(T)
    return sp.csr_matrix((out.data, (out.row * (c + 1), out.col)), shape=(T.shape[0] * (c + 1), T.shape[1]))
