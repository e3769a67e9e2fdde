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

    def face(self, mu: np.ndarray, gap: np.ndarray, c: float, weights: np.ndarray | None = None,
             mus: tuple = ()) -> np.ndarray:
        """Boolean mask of the rows held as equalities by the certificate's exact step (the active face),
        ``c`` converting a gap into a force (1 / mean diagonal of the Delassus matrix). ``weights``/``mus`` are
        passed only to a law whose method takes them (:func:`dualfem.core.constraints.call_law`)."""
        raise NotImplementedError

    def complementary(self, mu: np.ndarray, gap: np.ndarray, weights: np.ndarray, mus: tuple = ()) -> np.ndarray:
        """The multipliers (forces) that make each row complementary at its ``gap``: 0 for an open Signorini
        row, ``-g w sign(gap)`` for a sliding Tresca row. The certificate's step holds the rows off the face
        at them, and the evaluator's complementarity of a row is at most ``|mu - complementary| |g_j|_inf /
        f_s`` (the stationarity residual that moving mu there would cost)."""
        raise NotImplementedError

    def face_holds(self, mu1: np.ndarray, gap1: np.ndarray, face: np.ndarray, mu_margin: float,
                   gap_margin: float, weights: np.ndarray | None = None, mus: tuple = ()) -> bool:
        """Whether the exact point of the face (multipliers ``mu1``, gaps ``gap1``; ``face`` the rows held as
        equalities) keeps the law's conditions with margins (forces ``mu_margin``, lengths ``gap_margin``):
        then it is the solution, and the certificate's step to it measures the error."""
        raise NotImplementedError

    def conic(self) -> str | None:
        """The cone (one of :data:`CONES`) that ``G x`` must lie in, or None when the law is not a
        constraint ``G x in cone`` with fixed data (friction: a term of the objective); a conic backend
        handles a block only through this description (or :meth:`norm_term`)."""
        return None

    def certificate_note(self) -> str:
        """What the certificate of a QP with this law measures, when it is not plainly the QP's own error (a
        note in ``info["certificate"]["notes"]``); "" for a convex law."""
        return ""

    def norm_term(self, weights: np.ndarray) -> np.ndarray | None:
        """Per node j, the radius r_j (force) of an objective term ``sum_j r_j ||s_j||`` with fixed data (``s_j``
        the ``components`` rows of node j), for the conic backends' epigraph (:mod:`dualfem.numerics.epigraph`);
        None when the law is no such term (Signorini: a cone; Coulomb: its radius depends on the answer)."""
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

    def face(self, mu, gap, c, weights=None, mus=()):
        return (np.asarray(mu, float) - c * gap) > 0

    def complementary(self, mu, gap, weights=None, mus=()):
        return np.zeros(np.shape(mu))

    def face_holds(self, mu1, gap1, face, mu_margin, gap_margin, weights=None, mus=()):
        return bool(mu1[face].min(initial=np.inf) > mu_margin and gap1[~face].min(initial=np.inf) > gap_margin)

    def conic(self):
        return "nonneg"


#: the one instance of today's law
SIGNORINI = Signorini()


# ------------------------------------------------------------------------------------------------ friction
def _digest(a) -> str:
    """A short content digest of a law parameter (its repr enters :meth:`dualfem.core.qp.QP.key`)."""
    import hashlib

    arr = np.ascontiguousarray(np.asarray(a, dtype=float))
    return f"{arr.shape}:{hashlib.sha1(arr.tobytes()).hexdigest()[:16]}"


class Friction(Law):
    """Common part of the friction laws: a block of tangential jumps, ``components`` rows per friction node
    (1 in 2D: the jump along the tangent; 2 in 3D: along the two tangents of the node's frame), node-major
    (rows ``j * components + k``), the node's weight w_j (length) repeated on each of its rows.

    The multipliers of node j, ``mu_j`` (``components`` forces), lie in the disc (2D: the interval)
    ``||mu_j|| <= r_j``, the node's radius (a force: :meth:`radius`); the friction force opposes the slip:
    ``mu_j = -r_j s_j / ||s_j||`` where the tangential jump ``s_j = (G x)_j != 0``, any ``mu_j`` in the disc
    where ``s_j = 0`` (stick). The sign is that of :class:`dualfem.core.qp.QP` (``K x - F = G' mu``). There is
    no primal constraint (:meth:`primal` is 0): friction is a term of the objective (Tresca) or a threshold
    given by the normal multipliers (Coulomb)."""

    components: int = 1

    def radius(self, weights: np.ndarray, mus: tuple = ()) -> np.ndarray:
        """Per friction node, the disc radius r_j (force)."""
        raise NotImplementedError

    def nodes(self, v: np.ndarray) -> np.ndarray:
        """A stacked row vector of the block as (nodes, components)."""
        return np.asarray(v, float).reshape(-1, self.components)

    def _rows(self, per_node: np.ndarray) -> np.ndarray:
        return np.repeat(per_node, self.components)

    def _node_weights(self, weights) -> np.ndarray:
        return np.asarray(weights, float)[::self.components]

    def project(self, mu, weights=None, mus=()):
        r, m = self.radius(weights, mus), self.nodes(mu)
        norm = np.linalg.norm(m, axis=1)
        scale = np.where(norm > r, r / np.where(norm > 0, norm, 1.0), 1.0)
        return (m * scale[:, None]).ravel()

    def primal(self, gap):
        return 0.0

    def dual(self, mu, weights=None, mus=()):
        excess = np.linalg.norm(self.nodes(mu), axis=1) - self.radius(weights, mus)
        return float(np.maximum(excess, 0.0).max(initial=0.0))

    def complementarity(self, mu_s, gap_s, weights=None, fs=1.0, mus=()):
        """``|r_j / f_s ||s_j|| + mu_j . s_j / f_s|`` in the scaled units (0 iff mu_j opposes the slip with the full
        radius, given ``||mu_j|| <= r_j``), on each row of the node."""
        m, s = self.nodes(mu_s), self.nodes(gap_s)
        r = self.radius(weights, mus) / fs
        return self._rows(np.abs(r * np.linalg.norm(s, axis=1) + np.einsum("ij,ij->i", m, s)))

    def support(self, mu, gap, weights=None, mus=()):
        """``sum_j r_j ||s_j|| + mu_j . s_j`` (>= 0 for mu in the discs)."""
        m, s = self.nodes(mu), self.nodes(gap)
        return float(self.radius(weights, mus) @ np.linalg.norm(s, axis=1) + np.einsum("ij,ij->", m, s))

    def face(self, mu, gap, c, weights=None, mus=()):
        """Stick nodes: the trial force ``mu_j - c s_j`` inside the disc (both rows of a node held at s_j = 0)."""
        trial = self.nodes(mu) - c * self.nodes(gap)
        return self._rows(np.linalg.norm(trial, axis=1) < self.radius(weights, mus))

    def complementary(self, mu, gap, weights=None, mus=()):
        """``-r_j s_j / ||s_j||`` on slipping nodes; the projected mu_j on nodes without slip."""
        m, s = self.nodes(mu), self.nodes(gap)
        r = self.radius(weights, mus)
        norm = np.linalg.norm(s, axis=1)
        slip = norm > 0
        out = self.nodes(self.project(mu, weights, mus))
        out[slip] = -(r[slip] / norm[slip])[:, None] * s[slip]
        return out.ravel() if m.size else np.zeros(0)

    def face_holds(self, mu1, gap1, face, mu_margin, gap_margin, weights=None, mus=()):
        """Stick nodes strictly inside their discs (by ``mu_margin``); nodes of radius 0 at mu_j = 0; slipping
        nodes held at ``-r_j d_j`` (d_j the unit direction of their force) sliding along ``d_j``'s opposite by more
        than ``gap_margin`` and with no slip across it beyond rounding (in 3D the held direction must be the exact
        one: otherwise the step is not onto the solution and no value is claimed)."""
        m, s = self.nodes(mu1), self.nodes(gap1)
        stick = np.asarray(face, bool)[::self.components]
        if weights is None:
            return False
        r = self.radius(weights, mus)
        if np.any(np.linalg.norm(m[stick], axis=1) >= r[stick] - mu_margin):
            return False
        free = ~stick & (r <= 0)          # radius 0 (no friction there): held at mu_j = 0, any slip
        if np.any(m[free] != 0):
            return False
        ms, ss = m[~stick & ~free], s[~stick & ~free]
        mn = np.linalg.norm(ms, axis=1)
        if np.any(mn <= 0):
            return False
        d = ms / mn[:, None]
        along = -np.einsum("ij,ij->i", d, ss)
        across = np.linalg.norm(ss + along[:, None] * d, axis=1)
        # the held direction is exact only when the slip keeps it: across it, rounding only (1e-8 relative)
        tol = np.minimum(gap_margin, 1e-8 * np.linalg.norm(ss, axis=1))
        return bool(np.all(along > gap_margin) and np.all(across <= tol))


class Tresca(Friction):
    """Tresca (given) friction: radius ``r_j = g_j w_j`` with the threshold g_j >= 0 (stress units) per friction
    node (``bound``: a number or one value per node) and objective term ``sum_j g_j w_j ||s_j||`` (energy). The
    QP stays convex: its duality gap, face step and error bounds hold as for Signorini."""

    name = "tresca"

    def __init__(self, bound, components: int = 1):
        b = np.asarray(bound, dtype=float)
        if b.ndim > 1 or not np.all(np.isfinite(b)) or np.any(b < 0):
            raise ValueError("Tresca bound must be a finite number >= 0 or one such value per friction node")
        if components not in (1, 2):
            raise ValueError(f"Tresca components must be 1 (2D) or 2 (3D), got {components}")
        self.bound, self.components = (float(b) if b.ndim == 0 else b), int(components)

    def radius(self, weights, mus=()):
        return self.bound * self._node_weights(weights)

    def energy(self, gap, weights):
        return float(self.radius(weights) @ np.linalg.norm(self.nodes(gap), axis=1))

    def norm_term(self, weights):
        """The radii ``g_j w_j`` (forces): Tresca's objective term is ``sum_j g_j w_j ||s_j||``."""
        return self.radius(weights)

    def __repr__(self) -> str:
        b = self.bound if np.ndim(self.bound) == 0 else _digest(self.bound)
        return f"Tresca(bound={b}, components={self.components})"


class Coulomb(Friction):
    """Coulomb friction: radius ``r_j = mu_f,j max(lambda_j, 0)`` where lambda_j is the normal multiplier (force)
    of row ``normal_rows[j]`` of block ``normal_block`` (the Signorini block 0 by default; ``normal_rows`` None:
    rows 0..nodes-1) and ``coefficient`` mu_f >= 0 (a number or one per node). A quasi-variational problem: no
    energy of its own (:meth:`energy` is 0) and no duality gap; its residuals, and the certificate of the Tresca
    problem whose threshold is the answer's own ``mu_f lambda``, are what can be checked."""

    name = "coulomb"

    def __init__(self, coefficient, components: int = 1, normal_block: int = 0, normal_rows=None):
        c = np.asarray(coefficient, dtype=float)
        if c.ndim > 1 or not np.all(np.isfinite(c)) or np.any(c < 0):
            raise ValueError("Coulomb coefficient must be a finite number >= 0 or one such value per friction node")
        if components not in (1, 2):
            raise ValueError(f"Coulomb components must be 1 (2D) or 2 (3D), got {components}")
        self.coefficient = float(c) if c.ndim == 0 else c
        self.components, self.normal_block = int(components), int(normal_block)
        self.normal_rows = None if normal_rows is None else np.asarray(normal_rows, dtype=np.int64)

    def normal(self, mus: tuple, count: int) -> np.ndarray:
        """The normal multipliers lambda_j (forces) of the block's ``count`` nodes, from the QP's blocks ``mus``."""
        lam = np.asarray(mus[self.normal_block], float)
        return lam[:count] if self.normal_rows is None else lam[self.normal_rows]

    def radius(self, weights, mus=()):
        count = len(self._node_weights(weights))
        if not mus:
            raise ValueError("Coulomb's radius needs the normal multipliers (mus)")
        return self.coefficient * np.maximum(self.normal(mus, count), 0.0)

    def energy(self, gap, weights):
        return 0.0

    def certificate_note(self) -> str:
        return ("coulomb: certified as the Tresca problem whose threshold is the answer's own mu_f max(lambda, 0) "
                "(Coulomb friction is quasi-variational: no duality gap of its own; the bound is that Tresca "
                "problem's error)")

    def __repr__(self) -> str:
        c = self.coefficient if np.ndim(self.coefficient) == 0 else _digest(self.coefficient)
        rows = None if self.normal_rows is None else _digest(self.normal_rows)
        return f"Coulomb(coefficient={c}, components={self.components}, normal_block={self.normal_block}, rows={rows})"
