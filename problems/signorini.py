"""Signorini contact: an elastic rectangle pressed onto a rigid foundation (frictionless, or with friction).

Body: the rectangle (0, width) x (0, height), isotropic linear elasticity (E, nu, plane strain or
stress), P1 elements on an ``N x round(N height / width)`` grid of squares cut by the (1, 1)
diagonal (``MeshTri.init_tensor``). Left and right sides are traction-free.

Loading: a rigid flat frictionless punch on the top side pushes the body down by ``indent``
onto a fixed rigid foundation. Displacements are measured in the frame of the punch (they
differ from those in the frame of the foundation by the rigid translation ``(0, -indent)``,
which changes neither strains, stresses nor contact forces): ``u2 = 0`` on every top node,
``u1`` free there (frictionless punch) except at the top node nearest to ``width / 2``, where
``u1 = 0`` removes the horizontal rigid motion. So every eliminated (Dirichlet) component is
zero, as in the thin-defect scene, and tools that read ``qp.geometry`` need nothing new.

Foundation: ``obstacle`` is the initial gap ``g(x)`` >= 0 between the bottom point ``(x, 0)``
of the undeformed body and the foundation, measured along ``-x2`` (a numpy expression in ``x``;
default ``"0.05*(x-0.5)**2"``, a cylinder-like bump; ``"0"`` a flat foundation). In the frame of
the punch the foundation surface is at ``x2 = indent - g(x1)``; non-penetration at every bottom
node j is ``u2_j + g_j - indent >= 0``.

QP (see :mod:`dualfem.qp`): the unknowns are the free dofs; B row j picks ``u2`` of bottom node j
and ``Bx`` is the current gap to the foundation. Because the QP type has no constraint offset,
the offset is removed by the shift ``u = x + x_shift``, ``x_shift = B'(indent - g)``
(``B x_shift = indent - g``): the solvers' ``x`` is that shifted vector and
``K x - F = B'mu`` with ``F = -K x_shift``. ``qp.shift.x`` and ``qp.shift.objective``
recover the displacement ``u = x + x_shift`` and the potential energy
``Pi(u) = 1/2 u'Ku = qp.energy(x) + objective_offset``. The multipliers are the nodal contact
forces (>= 0, force per unit thickness); the contact pressure is ``mu / weights`` with trapezoid
weights along the bottom side.

Friction on the foundation (docs/friction.md): ``friction`` = "none" (default) | "tresca" | "coulomb",
``friction_bound`` (Tresca's threshold, a stress: a number or an expression in x, y, evaluated at the bottom
nodes) or ``friction_coefficient`` (Coulomb's mu_f): one more constraint block whose row j is ``u1`` of bottom
node j (the foundation does not move along x), weighted like B's rows (:mod:`._friction_keys`).

Checkable physics (tests/test_signorini.py):

* ``obstacle = "0"``: the exact solution is homogeneous uniaxial compression, reproduced exactly
  by P1: contact pressure ``p = E' indent / height`` on the whole bottom, with ``E' = E / (1 - nu^2)``
  (plane strain) or ``E`` (plane stress), and ``u2 = indent (1 - x2 / height)``.
* any obstacle: global equilibrium, total contact force = the punch force (:meth:`Signorini.punch_force`,
  computed from the rows of the full stiffness matrix for the clamped dofs, which the QP does
  not contain), and zero horizontal reaction at the pin (frictionless contact).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.core.elasticity import PLANES, lame
from dualfem.core.expressions import compile_expression
from dualfem.errors import InputError, check_int, check_open_interval, check_positive
from dualfem.problem import Problem, UnitMap
from dualfem.qp import QP, GeometryPart, MaterialPart, ShiftPart, UnitsPart
from dualfem.registry import register_problem

from . import _friction_keys as fk

#: the most grid squares a scene may have (N = 4096 on a square body; the N range's top): checked in validate,
#: before anything is allocated, since height / width multiplies the rows of the grid
MAX_CELLS = 4096 ** 2


def gap_function(expr: str):
    """The initial gap ``g(x)`` from a numpy expression in ``x`` (or a Python function).

    Checked and evaluated by the one expression sandbox, :mod:`dualfem.core.expressions` (the same
    size limits, vocabulary and float-only evaluation as a load expression).
    """
    if callable(expr):
        return expr
    if not isinstance(expr, (str, int, float)) or isinstance(expr, bool):
        raise InputError(f"obstacle must be a numpy expression in x (e.g. '0.5*(x-0.5)**2'), got {expr!r}")
    return compile_expression(str(expr), parameter="obstacle", variables=("x",),
                              hint="use a numpy expression in x, e.g. '0.5*(x-0.5)**2'")


@register_problem
class Signorini(Problem):
    """Elastic rectangle pressed by a flat punch onto a rigid foundation (Signorini contact)."""

    name = "signorini"
    description = "elastic rectangle pressed onto a rigid foundation (Signorini contact, frictionless)"
    dim = 2
    #: the stress grid's units axis: the gap obstacle(x) is a length, length * g(x / length)
    unit_map = UnitMap({"E": "stress", "width": "length", "height": "length", "indent": "length",
                        "obstacle": "length_field", "friction_bound": "stress_value"})
    defaults = {
        "N": 32,
        "E": 69000.0,
        "nu": 0.3,
        "plane": "strain",
        "width": 1.0,
        "height": 0.5,
        "indent": 0.005,
        "obstacle": "0.05*(x-0.5)**2",
        **fk.DEFAULTS,
    }
    presets = {"signorini": {}, "signorini_flat": {"obstacle": "0"}}
    requires = ("skfem",)

    def validate(self) -> None:
        p = self.params
        p["N"] = check_int("N", p["N"], 2, 4096)
        p["E"] = check_positive("E", p["E"])
        p["nu"] = check_open_interval("nu", p["nu"], -1.0, 0.5)
        p["width"] = check_positive("width", p["width"])
        p["height"] = check_positive("height", p["height"])
        p["indent"] = check_positive("indent", p["indent"], allow_zero=True)
        nx, ny = self.grid()
        if nx * ny > MAX_CELLS:      # before anything is allocated: height / width multiplies the rows
            raise InputError(f"the grid N x round(N height / width) = {nx} x {ny:,} (N = {nx}, height / width = "
                             f"{p['height'] / p['width']:g}) has more than {MAX_CELLS:,} squares (N = 4096 on a square "
                             f"body): lower N or height / width")
        if p["plane"] not in PLANES:
            raise InputError(f"plane must be one of {', '.join(PLANES)}, got {p['plane']!r}")
        (self._friction,) = fk.parse_friction(p, [{}], 2, (p["width"], p["height"]))
        self._gap = gap_function(p["obstacle"])
        xs = np.linspace(0.0, p["width"], 9)
        try:
            g = self._gap(xs)
        except Exception as exc:
            raise InputError(f"obstacle {p['obstacle']!r} cannot be evaluated: {exc}") from None
        if not np.all(np.isfinite(g)):
            raise InputError(f"obstacle {p['obstacle']!r} gives NaN or infinite gaps on [0, {p['width']:g}]")
        if np.any(g < 0):
            raise InputError(f"obstacle {p['obstacle']!r} gives a negative initial gap (the foundation would "
                             f"already penetrate the body); the gap g(x) must be >= 0 on [0, {p['width']:g}]")

    def grid(self) -> tuple[int, int]:
        """(squares along x, squares along y) of the mesh: ``(N, max(1, round(N height / width)))``."""
        p = self.params
        ratio = float(p["height"]) / float(p["width"])
        rows = p["N"] * ratio
        return p["N"], max(1, int(round(rows))) if np.isfinite(rows) and rows < 2.0 ** 62 else 2 ** 62

    def size_estimate(self) -> tuple[int, str]:
        """Unknowns before assembly: 2 per grid node (an upper bound: the Dirichlet nodes are counted)."""
        nx, ny = self.grid()
        return 2 * (nx + 1) * (ny + 1), f"N={nx} (grid {nx} x {ny})"

    def mesh(self):
        """The scikit-fem mesh of the rectangle."""
        from skfem import MeshTri

        p = self.params
        _, ny = self.grid()
        return MeshTri.init_tensor(np.linspace(0, p["width"], p["N"] + 1), np.linspace(0, p["height"], ny + 1))

    def build(self) -> QP:
        from skfem import Basis, ElementTriP1, ElementVector, asm
        from skfem.models.elasticity import linear_elasticity

        p = self.params
        mesh = self.mesh()
        basis = Basis(mesh, ElementVector(ElementTriP1()))
        lam, mu = lame(p["E"], p["nu"], p["plane"])
        K_all = asm(linear_elasticity(lam, mu), basis).tocsr()
        X = mesh.p
        W, H = p["width"], p["height"]
        tol = 1e-9 * max(W, H)
        nd = basis.nodal_dofs                       # (2, nnodes) global dof ids
        top = np.flatnonzero(np.abs(X[1] - H) < tol)
        bottom = np.flatnonzero(np.abs(X[1]) < tol)
        bottom = bottom[np.argsort(X[0, bottom])]
        pin = top[np.argmin(np.abs(X[0, top] - 0.5 * W))]
        prescribed = np.concatenate([nd[1, top], [nd[0, pin]]])     # all held at 0
        free = np.setdiff1d(np.arange(basis.N), prescribed)
        g2f = np.full(basis.N, -1, dtype=np.int64)
        g2f[free] = np.arange(free.size)
        node_dofs = g2f[nd]

        K = K_all[free][:, free].tocsc()
        m = bottom.size
        cols = node_dofs[1, bottom]
        B = sp.csr_matrix((np.ones(m), (np.arange(m), cols)), shape=(m, free.size))
        xb = X[0, bottom]
        seg = np.diff(xb)
        weights = 0.5 * (np.r_[0.0, seg] + np.r_[seg, 0.0])
        gap = self._gap(xb)
        shift = B.T @ (p["indent"] - gap)           # u = x + shift, B shift = indent - gap
        F = -(K @ shift)                            # no external load: the indentation drives it
        offset = float(0.5 * shift @ (K @ shift))
        local = np.unique(node_dofs[:, bottom][node_dofs[:, bottom] >= 0])

        # what the punch-force check needs and the QP does not contain
        self._K_pf = K_all[prescribed][:, free].tocsr()
        self._n_top = top.size
        self._shift = shift
        maps = {
            "contact_nodes": bottom, "contact_x": xb, "gap": gap, "normal": np.array([0.0, -1.0]),
            "top_nodes": top, "pin_node": np.array(pin),
        }
        params = {k: (v if isinstance(v, (int, float, str)) else str(v)) for k, v in p.items() if k not in fk.KEYS}
        if self._friction.kind != "none":
            params["friction"] = fk.params_label([self._friction])
        qp = QP(K=K, F=F, B=B, weights=weights, K_fixed=K, local_dofs=local,
                name=f"signorini[{'flat' if not np.any(gap) else 'obstacle'}]", params=params, maps=maps,
                shift=ShiftPart.make(shift, offset), geometry=GeometryPart.make(X, mesh.t, node_dofs),
                units=UnitsPart(E=float(p["E"]), length=float(p["width"])),
                material=MaterialPart(float(p["E"]), float(p["nu"]), str(p["plane"])))
        # friction on the foundation: the tangential displacement u1 of each bottom node (the foundation does not
        # move along x in the punch's frame), weighted like B's rows
        G_t = sp.csr_matrix((np.ones(m), (np.arange(m), node_dofs[0, bottom])), shape=(m, free.size))
        return fk.boundary_friction(qp, self._friction, G_t, weights, X[:, bottom])

    def displacement(self, x: np.ndarray) -> np.ndarray:
        """The displacement of the free dofs, ``u = x + x_shift`` (call :meth:`build` first)."""
        return np.asarray(x) + self._shift

    def punch_force(self, x: np.ndarray) -> tuple[float, float]:
        """(total vertical force of the punch on the body, horizontal force at the pin).

        Reactions at the clamped dofs, ``K_pf u_f`` (their own displacements are 0), from rows of
        the full stiffness matrix that the QP does not hold. Equilibrium: vertical force + sum(mu) = 0.
        """
        r = self._K_pf @ self.displacement(x)
        return float(r[: self._n_top].sum()), float(r[self._n_top])

    def flat_pressure(self) -> float:
        """Exact contact pressure on a flat foundation: E' indent / height."""
        p = self.params
        Eeff = p["E"] / (1 - p["nu"] ** 2) if p["plane"] == "strain" else p["E"]
        return Eeff * p["indent"] / p["height"]
