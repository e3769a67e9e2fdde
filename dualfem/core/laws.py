"""Constraint laws: what a constraint block ``(G, weights, law)`` asks of ``g = G x`` and of its multipliers.

A law owns everything that depends on the kind of constraint (PERMON's QPC objects in spirit): the
projection onto its dual set, its primal / dual / complementarity residuals (the evaluator calls them),
its conic description (for the conic backends), the support term of the duality gap and the face
(active-set) guess of the certificate. The core, the evaluator and the certificate never test
``max(0, -Gx)`` or ``mu >= 0`` themselves.

Conventions, for a block of m rows with operator G (m, n), nodal weights w (m,) and multipliers mu (m,):

* ``gap = G x`` (lengths; for a shifted frame ``G y - h``), ``mu`` forces (force per unit thickness),
  with ``K x - F = sum_blocks G' mu`` at the solution (the sign of :class:`dualfem.core.qp.QP`);
* :meth:`Law.project` maps mu onto the law's dual set (the set the multipliers of a solution lie in);
* residual methods return *violations* (0 at a solution), in the units stated on each method;
* ``mus``: the multipliers of every block of the QP, in block order (a law coupling two blocks, such as
  Coulomb friction whose disc radius is a coefficient times the normal multiplier, reads its partner
  block there); laws of one block ignore it.

A third-party law subclasses :class:`Law`, gives it a ``name`` (the word :attr:`dualfem.core.solver.Solver.accepts`
lists) and implements the methods; a solver that does not list the name is skipped, never run on it.
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np

#: the cone kinds of :meth:`Law.conic` (the conic backends map them to their own cone types):
#: ``"zero"`` (G x = 0), ``"nonneg"`` (G x >= 0)
CONES: tuple[str, ...] = ("zero", "nonneg")


class Law:
    """Base class of a constraint law (see the module docstring). Subclasses set ``name`` and implement
    every method; the defaults raise NotImplementedError (a law that cannot say is never guessed)."""

    #: the law's name: the word a solver's ``accepts`` lists
    name: ClassVar[str] = ""

    def project(self, mu: np.ndarray, weights: np.ndarray, mus: tuple = ()) -> np.ndarray:
        """mu projected onto the dual set of the law (forces)."""
        raise NotImplementedError

    def primal(self, gap: np.ndarray) -> float:
        """The largest violation of the primal constraint by ``gap`` (lengths; 0 when satisfied)."""
        raise NotImplementedError

    def dual(self, mu: np.ndarray, weights: np.ndarray, mus: tuple = ()) -> float:
        """The largest violation of the dual set by ``mu`` (forces; 0 inside)."""
        raise NotImplementedError

    def complementarity(self, mu_s: np.ndarray, gap_s: np.ndarray, weights: np.ndarray | None = None,
                        fs: float = 1.0, mus: tuple = ()) -> np.ndarray:
        """Per-row complementarity violation from the scaled ``mu_s = mu / f_s`` and ``gap_s = gap / l_s``
        (dimensionless; the evaluator takes the smaller of it and the force the row carries). ``fs``: the force
        scale, for a law whose dual set has a size of its own (Tresca's bound g w / f_s); ``mus`` unscaled."""
        raise NotImplementedError

    def energy(self, gap: np.ndarray, weights: np.ndarray) -> float:
        """The law's term of the objective at ``gap`` (energy; 0 for a constraint such as Signorini, whose
        indicator is 0 on the feasible set; ``sum_j g w_j |gap_j|`` for Tresca friction)."""
        raise NotImplementedError

    def support(self, mu: np.ndarray, gap: np.ndarray, weights: np.ndarray, mus: tuple = ()) -> float:
        """The block's term of the duality gap ``Pi(x) - D(mu)`` beyond 1/2 |x - z|_K^2, for a primal
        feasible ``gap`` and a dual feasible (projected) ``mu`` (energy: force x length; >= 0 there)."""
        raise NotImplementedError

    def face(self, mu: np.ndarray, gap: np.ndarray, c: float) -> np.ndarray:
        """Boolean mask of the rows held as equalities by the certificate's exact step (the active face),
        ``c`` converting a gap into a force (1 / mean diagonal of the Delassus matrix)."""
        raise NotImplementedError

    def complementary(self, mu: np.ndarray, gap: np.ndarray, weights: np.ndarray, mus: tuple = ()) -> np.ndarray:
        """The multipliers (forces) that make each row complementary at its ``gap``: 0 for an open Signorini
        row, ``-g w sign(gap)`` for a sliding Tresca row. The certificate's step holds the rows off the face
        at them, and the evaluator's complementarity of a row is at most ``|mu - complementary| |g_j|_inf /
        f_s`` (the stationarity residual that moving mu there would cost)."""
        raise NotImplementedError

    def face_holds(self, mu1: np.ndarray, gap1: np.ndarray, face: np.ndarray, mu_margin: float,
                   gap_margin: float) -> bool:
        """Whether the exact point of the face (multipliers ``mu1``, gaps ``gap1``; ``face`` the rows held as
        equalities) keeps the law's conditions with margins (forces ``mu_margin``, lengths ``gap_margin``):
        then it is the solution, and the certificate's step to it measures the error."""
        raise NotImplementedError

    def conic(self) -> str | None:
        """The cone (one of :data:`CONES`) that ``G x`` must lie in, or None when the law is not a
        constraint ``G x in cone`` with fixed data (friction: a term of the objective); a conic backend
        handles a block only through this description."""
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def __eq__(self, other: object) -> bool:
        """Equal: the same class with equal parameters (a law with array parameters: only itself)."""
        try:
            return type(other) is type(self) and bool(vars(other) == vars(self))
        except ValueError:          # array-valued parameters: their comparison has no single truth value
            return other is self

    def __hash__(self) -> int:
        return hash(type(self))


class Signorini(Law):
    """Unilateral contact: ``G x >= 0`` (no interpenetration), ``mu >= 0`` (compression),
    ``mu_j (G x)_j = 0``: today's law of every QP (the block ``(qp.B, qp.weights)``)."""

    name = "signorini"

    def project(self, mu, weights=None, mus=()):
        return np.maximum(mu, 0.0)

    def primal(self, gap):
        return max(0.0, -gap.min(initial=0.0))

    def dual(self, mu, weights=None, mus=()):
        return max(0.0, -mu.min(initial=0.0))

    def complementarity(self, mu_s, gap_s, weights=None, fs=1.0, mus=()):
        return np.abs(mu_s * gap_s)

    def energy(self, gap, weights=None):
        return 0.0

    def support(self, mu, gap, weights=None, mus=()):
        return float(mu @ gap)

    def face(self, mu, gap, c):
        return (np.asarray(mu, float) - c * gap) > 0

    def complementary(self, mu, gap, weights=None, mus=()):
        return np.zeros(np.shape(mu))

    def face_holds(self, mu1, gap1, face, mu_margin, gap_margin):
        return bool(mu1[face].min(initial=np.inf) > mu_margin and gap1[~face].min(initial=np.inf) > gap_margin)

    def conic(self):
        return "nonneg"


#: the one instance of today's law
SIGNORINI = Signorini()
