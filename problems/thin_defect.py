"""The thin-defect scene of Zhiltsov & Maksimova (2023) as a QP.

Body: the rectangle (0, width) x (0, height) (unit square by default), isotropic linear
elasticity (E, nu; ``plane = "strain"`` by default, ``"stress"`` supported: the paper does not
say which it used), clamped on the bottom side x2 = 0, a traction on the top side x2 = height,
other sides free. Defect gamma0: a straight segment from ``defect[0]`` to ``defect[1]``; its
normal nu is the tangent turned by +90 degrees (for the default horizontal defect, nu = (0, 1),
so the "+" / upper face is above). Energy (paper, section 1):

    Pi(v) = 1/2 a(v, v) - (f, v) + 1/(2 delta) int_gamma0 |[v]|^2,     [v_nu] >= 0 on gamma0.

Discretization: N x N squares, each cut by the diagonal in the (1, 1) direction (scikit-fem's
``MeshTri.init_tensor``), P1 vector elements. The nodes strictly inside the defect are doubled
(the original node is the lower copy, a new node at the same place the upper copy; triangles on
the +nu side use the upper copies); the two tips are not doubled. The interface integral uses
the trapezoid rule: weight w_j = half the sum of the lengths of the two defect edges at node j.

Units are whatever the inputs use (paper: MPa and a unit length). The QP and its multiplier
convention are described in :mod:`dualfem.qp`.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualfem.core.elasticity import PLANES, lame
from dualfem.core.errors import InputError, check_int, check_open_interval, check_positive
from dualfem.core.problem import Problem
from dualfem.core.qp import QP
from dualfem.core.registry import register_problem

from .loads import resolve_load


def _parse_defect(value) -> np.ndarray:
    if isinstance(value, str):
        try:
            nums = [float(s) for s in value.replace(";", ",").replace(" ", ",").split(",") if s]
        except ValueError:
            nums = []
        value = nums
    try:
        arr = np.asarray(value, dtype=float).reshape(2, 2)
    except (ValueError, TypeError):
        raise InputError(f"defect must be two points [[x1, y1], [x2, y2]] (or 'x1,y1,x2,y2'), got {value!r}") from None
    if not np.all(np.isfinite(arr)):
        raise InputError(f"defect coordinates must be finite, got {value!r}")
    return arr


def _load_label(load) -> str:
    return repr(load) if isinstance(load, str) else getattr(load, "__name__", "function")


@register_problem
class ThinDefect(Problem):
    """Elastic rectangle with a straight thin defect (fracture parameter delta)."""

    name = "thin_defect"
    description = "2D elastic body with a thin defect (Zhiltsov & Maksimova 2023)"
    defaults = {
        "N": 64,
        "delta": 1e-5,
        "E": 69000.0,
        "nu": 0.3,
        "plane": "strain",
        "load": "f2",
        "load_scale": 1.0,
        "defect": ((0.25, 0.5), (0.75, 0.5)),
        "width": 1.0,
        "height": 1.0,
    }
    presets = {"f1": {"load": "f1"}, "f2": {"load": "f2"}, "f3": {"load": "f3"}}

    def validate(self) -> None:
        p = self.params
        p["N"] = check_int("N", p["N"], 2, 4096)
        p["delta"] = check_positive("delta", p["delta"])
        p["E"] = check_positive("E", p["E"])
        p["nu"] = check_open_interval("nu", p["nu"], -1.0, 0.5)
        p["width"] = check_positive("width", p["width"])
        p["height"] = check_positive("height", p["height"])
        ls = p["load_scale"]
        if not isinstance(ls, (int, float)) or not np.isfinite(ls):
            raise InputError(f"load_scale must be a finite number, got {ls!r}")
        if p["plane"] not in PLANES:
            raise InputError(f"plane must be one of {', '.join(PLANES)}, got {p['plane']!r}")
        p["defect"] = _parse_defect(p["defect"])
        with np.errstate(all="ignore"):  # a NaN-producing expression is refused below, without warnings
            self._traction = resolve_load(p["load"], p["width"])
        self._geometry_checks()

    def _geometry_checks(self) -> None:
        p = self.params
        a, b = p["defect"]
        W, H = p["width"], p["height"]
        if np.linalg.norm(b - a) <= 1e-12 * max(W, H):
            raise InputError(f"defect has zero length: both ends at {tuple(float(c) for c in a)}")
        for pt in (a, b):
            if not (0 < pt[0] < W and 0 < pt[1] < H):
                raise InputError(f"defect must lie strictly inside the domain (0, {W:g}) x (0, {H:g}); "
                                 f"endpoint {tuple(float(c) for c in pt)} touches or leaves it")

    # ----------------------------------------------------------------- mesh
    def mesh(self):
        """The scikit-fem mesh with doubled defect nodes, and the defect description."""
        if getattr(self, "_mesh", None) is not None:
            return self._mesh, self._defect
        from skfem import MeshTri

        p = self.params
        N, W, H = p["N"], p["width"], p["height"]
        base = MeshTri.init_tensor(np.linspace(0, W, N + 1), np.linspace(0, H, N + 1))
        a, b = p["defect"]
        L = np.linalg.norm(b - a)
        tau = (b - a) / L
        nu = np.array([-tau[1], tau[0]])
        h = min(W, H) / N
        tol = 1e-8 * h
        rel = base.p - a[:, None]
        s = tau @ rel
        dist = np.abs(nu @ rel)
        on = np.flatnonzero((dist < tol) & (s > -tol) & (s < L + tol))
        order = on[np.argsort(s[on])]
        s_on = s[order]
        if len(order) < 2 or abs(s_on[0]) > tol or abs(s_on[-1] - L) > tol:
            raise InputError(f"N={N} cannot carry the defect {a.tolist()} -> {b.tolist()}: its ends must be "
                             f"mesh nodes (multiples of width/N, height/N); choose N so that they are")
        edges = set(map(tuple, np.sort(base.facets.T, axis=1)))
        for i, j in zip(order[:-1], order[1:]):
            if (min(i, j), max(i, j)) not in edges:
                raise InputError(f"N={N} cannot carry the defect {a.tolist()} -> {b.tolist()}: it does not run "
                                 f"along mesh edges (allowed directions: horizontal, vertical, diagonal (1, 1))")
        interior = order[1:-1]
        if len(interior) == 0:
            raise InputError(f"N={N} is too coarse: the defect spans a single mesh edge, so no node can be "
                             f"doubled; increase N")
        # trapezoid weights of the interior nodes
        seg = np.diff(s_on)
        weights = 0.5 * (seg[:-1] + seg[1:])
        # double the interior nodes: new upper copies appended at the end
        nn = base.p.shape[1]
        upper = nn + np.arange(len(interior))
        newid = np.full(nn, -1)
        newid[interior] = upper
        t = base.t.copy()
        centroid = base.p[:, t].mean(axis=1)
        above = nu @ (centroid - a[:, None]) > 0
        touches = np.isin(t, interior).any(axis=0)
        cols = np.flatnonzero(above & touches)
        sub = t[:, cols]
        mask = np.isin(sub, interior)
        sub[mask] = newid[sub[mask]]
        t[:, cols] = sub
        pts = np.hstack([base.p, base.p[:, interior]])
        mesh = MeshTri(pts, t)
        defect = {
            "lower": interior, "upper": upper, "tips": order[[0, -1]], "s": s_on[1:-1],
            "weights": weights, "normal": nu, "tangent": tau,
        }
        self._mesh, self._defect = mesh, defect
        return mesh, defect

    # ------------------------------------------------------------- assembly
    def basis(self):
        """P1 vector basis on the doubled mesh."""
        from skfem import Basis, ElementTriP1, ElementVector

        mesh, _ = self.mesh()
        return Basis(mesh, ElementVector(ElementTriP1()))

    def assemble(self):
        """Elastic stiffness and top-traction load on all DOFs (before boundary conditions).

        Returns ``(K_all, F_all, basis)``; scikit-fem's DOF numbering (``basis.nodal_dofs``).
        """
        from skfem import FacetBasis, LinearForm, asm
        from skfem.models.elasticity import linear_elasticity

        p = self.params
        mesh, _ = self.mesh()
        basis = self.basis()
        lam, mu = lame(p["E"], p["nu"], p["plane"])
        K_all = asm(linear_elasticity(lam, mu), basis)
        H = p["height"]
        top = mesh.facets_satisfying(lambda x: np.isclose(x[1], H), boundaries_only=True)
        fb = FacetBasis(mesh, basis.elem, facets=top, intorder=6)
        g = self._traction
        scale = float(p["load_scale"])

        @LinearForm
        def traction(v, w):
            val = g(w.x[0], w.x[1])
            if isinstance(val, tuple):
                return scale * (val[0] * v[0] + val[1] * v[1])
            return scale * val * v[1]

        with np.errstate(all="ignore"):
            try:
                F_all = asm(traction, fb)
            except InputError:
                raise
            except Exception as exc:  # a user-given load function that breaks
                raise InputError(f"load {_load_label(p['load'])} cannot be evaluated on the top side: "
                                 f"{type(exc).__name__}: {exc}") from None
        if not np.all(np.isfinite(F_all)):
            raise InputError(f"load {_load_label(p['load'])} gives NaN or infinite values on the top side "
                             f"(x2 = {H:g}, 0 <= x1 <= {p['width']:g}); it must be finite there")
        return K_all, F_all, basis

    def build(self) -> QP:
        """Assemble K (elastic + interface/delta), F (top traction), B (normal jumps)."""
        p = self.params
        _, dfc = self.mesh()
        mesh = self._mesh
        K_all, F_all, basis = self.assemble()
        clamped = basis.get_dofs(lambda x: np.isclose(x[1], 0.0)).all()
        free = np.setdiff1d(np.arange(basis.N), clamped)
        g2f = np.full(basis.N, -1, dtype=np.int64)
        g2f[free] = np.arange(free.size)
        node_dofs = g2f[basis.nodal_dofs]  # (2, nnodes) -> index in x, -1 if clamped

        K_el = K_all[free][:, free].tocsc()
        F = np.asarray(F_all[free], dtype=float)
        m = len(dfc["upper"])
        rows = np.arange(m)
        J = []
        for c in range(2):
            up, lo = node_dofs[c, dfc["upper"]], node_dofs[c, dfc["lower"]]
            J.append(sp.csr_matrix((np.r_[np.ones(m), -np.ones(m)], (np.r_[rows, rows], np.r_[up, lo])),
                                   shape=(m, free.size)))
        W = sp.diags(dfc["weights"])
        K_iface = (J[0].T @ W @ J[0] + J[1].T @ W @ J[1]).tocsc()
        K = (K_el + K_iface / p["delta"]).tocsc()
        nrm = dfc["normal"]
        B = (nrm[0] * J[0] + nrm[1] * J[1]).tocsr()
        B.eliminate_zeros()
        local = np.unique(np.concatenate([node_dofs[:, dfc["upper"]].ravel(), node_dofs[:, dfc["lower"]].ravel()]))
        maps = {
            "nodes": mesh.p, "triangles": mesh.t, "node_dofs": node_dofs,
            "defect_upper": dfc["upper"], "defect_lower": dfc["lower"], "defect_tips": dfc["tips"],
            "defect_s": dfc["s"], "normal": nrm, "tangent": dfc["tangent"],
        }
        params = {k: (v if isinstance(v, (int, float, str)) else str(np.asarray(v).tolist()))
                  for k, v in p.items() if not callable(v)}
        self.K_interface = K_iface
        self.jump_operators = J
        return QP(K=K, F=F, B=B, weights=dfc["weights"], K_fixed=K_el, local_dofs=local,
                  name=f"thin_defect[{p['load'] if isinstance(p['load'], str) else 'custom'}]",
                  params=params, maps=maps)
