"""A posteriori error estimator for 2D P1 elasticity with thin defects: Zienkiewicz-Zhu recovery.

The P1 stress ``sigma_h`` is constant per triangle. The recovered stress ``sigma*`` is continuous and
piecewise linear on the *doubled* (cut) mesh: at each node the area-weighted mean of ``sigma_h`` over
the triangles holding that node. Because the defect's interior nodes are doubled, a node on the "+" face
averages only the "+" side's triangles: the recovered field jumps across the defect as the true one does
(the tips, single nodes, average both sides). The defect term: at every doubled node the recovered
traction is replaced by the traction the defect actually carries there (:func:`face_tractions`), so
``sigma* . nu = [u] / delta - p nu`` with ``p`` the contact pressure (the QP's multiplier over the
node's weight) and ``[u] / delta`` the interface term of the energy; a P1 traction mismatch on the
faces (open or in contact) is thereby counted in the indicator of the face's triangles.

Indicator of triangle T (energy units, the energy norm ``||v||^2 = a(v, v) = x' K_el x``)::

    eta_T^2 = int_T (sigma* - sigma_h) : C^-1 (sigma* - sigma_h)

integrated exactly (the integrand is quadratic: the three edge midpoints with weight |T| / 3).
``eta^2 = sum eta_T^2``; the relative estimate is ``eta / sqrt(||u_h||^2 + eta^2)``.

The next mesh's sizes (:func:`equidistributed_sizes`, the adaptive loop's rule): the error density
c_T = eta_T^2 / h_T^(2p + d) per element, the sizes h'_T ~ c_T^(-1/(2p + d)) that give every element of the
new mesh the same predicted error, scaled to the target or the budget. :func:`optimal_sizes` is Zienkiewicz
& Zhu's 1987 rule ``h_T (e_bar / eta_T)^(1/p)`` (the loop's rule before: it over-refines the worst elements).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dualfem.core.errors import InputError

#: sqrt(3) / 4: the area of the equilateral triangle of edge 1 (sizes are equilateral edge lengths)
_EQUILATERAL = np.sqrt(3.0) / 4.0


@dataclass(frozen=True)
class Estimate:
    """The estimator's result on one mesh. ``eta2`` (nt,): eta_T^2 per triangle; ``energy2`` (nt,):
    ``int_T sigma_h : eps_h`` (``sum = ||u_h||^2``); ``area`` (nt,); the totals ``eta`` (energy-norm units,
    sqrt(energy)) and ``relative`` = eta / sqrt(||u_h||^2 + eta^2)."""

    eta2: np.ndarray
    energy2: np.ndarray
    area: np.ndarray
    #: 2 (triangles; ``area`` their areas) or 3 (tetrahedra; ``area`` their volumes)
    dim: int = 2
    #: the energy error's order p in h where the solution is smooth (the optimal-mesh rule): 1 P1, 2 P2
    order: float = 1.0

    @property
    def eta(self) -> float:
        return float(np.sqrt(self.eta2.sum()))

    @property
    def energy(self) -> float:
        """||u_h|| in the energy norm."""
        return float(np.sqrt(self.energy2.sum()))

    @property
    def relative(self) -> float:
        tot = self.eta2.sum() + self.energy2.sum()
        return float(np.sqrt(self.eta2.sum() / tot)) if tot > 0 else 0.0

    @property
    def sizes(self) -> np.ndarray:
        """Each element's size: the edge of the equilateral triangle of its area (the regular tetrahedron of
        its volume, V = h^3 / (6 sqrt 2))."""
        if self.dim == 3:
            return np.cbrt(6 * np.sqrt(2.0) * self.area)
        return np.sqrt(self.area / _EQUILATERAL)


def _gradients(nodes: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P1 gradients (nt, 3, 2) and areas (nt,) of counter-clockwise or clockwise triangles."""
    p = nodes[:, tri]                                                   # (2, 3, nt)
    x, y = p[0], p[1]
    two_a = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])
    j, k = [1, 2, 0], [2, 0, 1]
    g = np.stack([((y[j] - y[k]) / two_a).T, ((x[k] - x[j]) / two_a).T], axis=2)
    return g, 0.5 * np.abs(two_a)


def p1_stress(nodes: np.ndarray, tri: np.ndarray, u: np.ndarray, lam: float,
              mu: float) -> tuple[np.ndarray, np.ndarray]:
    """Stress (nt, 3) = (s11, s22, s12) per triangle of the nodal displacement ``u`` (n, 2), and the areas.
    ``lam``, ``mu``: the 2D Lame constants (plane stress: the effective lambda)."""
    g, area = _gradients(nodes, tri)
    du = np.einsum("tic,tid->tcd", u[tri.T], g)                         # du[t, c, d] = d u_c / d x_d
    tr = du[:, 0, 0] + du[:, 1, 1]
    s = np.stack([lam * tr + 2 * mu * du[:, 0, 0], lam * tr + 2 * mu * du[:, 1, 1],
                  mu * (du[:, 0, 1] + du[:, 1, 0])], axis=1)
    return s, area


def _energy_density(s: np.ndarray, lam: float, mu: float) -> np.ndarray:
    """sigma : C^-1 sigma for stresses (..., 3) = (s11, s22, s12) of 2D isotropic elasticity."""
    tr = s[..., 0] + s[..., 1]
    ss = s[..., 0] ** 2 + s[..., 1] ** 2 + 2 * s[..., 2] ** 2
    return (ss - lam / (2 * (lam + mu)) * tr ** 2) / (2 * mu)


def recovered_stress(tri: np.ndarray, s: np.ndarray, area: np.ndarray, n_nodes: int) -> np.ndarray:
    """Nodal stress (n, 3): the area-weighted mean of the triangles' stresses around each node."""
    w = np.bincount(tri.ravel(), weights=np.tile(area, 3), minlength=n_nodes)
    out = np.empty((n_nodes, 3))
    for c in range(3):
        out[:, c] = np.bincount(tri.ravel(), weights=np.tile(area * s[:, c], 3), minlength=n_nodes)
    return out / np.where(w > 0, w, 1.0)[:, None]


def impose_traction(sn: np.ndarray, normals: np.ndarray, traction: np.ndarray) -> np.ndarray:
    """Stresses (k, 3) changed as little as possible (a symmetric rank-2 update) so that sigma . n = t."""
    s = np.array(sn, dtype=float)
    n = np.asarray(normals, dtype=float)
    sig_n = np.stack([s[:, 0] * n[:, 0] + s[:, 2] * n[:, 1], s[:, 2] * n[:, 0] + s[:, 1] * n[:, 1]], axis=1)
    r = np.asarray(traction, dtype=float) - sig_n
    rn = np.sum(r * n, axis=1)
    # sigma + r n' + n r' - (r . n) n n'
    s[:, 0] += 2 * r[:, 0] * n[:, 0] - rn * n[:, 0] ** 2
    s[:, 1] += 2 * r[:, 1] * n[:, 1] - rn * n[:, 1] ** 2
    s[:, 2] += r[:, 0] * n[:, 1] + n[:, 0] * r[:, 1] - rn * n[:, 0] * n[:, 1]
    return s


def zz_estimate(nodes: np.ndarray, tri: np.ndarray, u: np.ndarray, lam: float, mu: float,
                faces: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> Estimate:
    """The ZZ estimate of the P1 displacement ``u`` (n, 2) on the mesh ``nodes`` (2, n), ``tri`` (3, nt).

    ``faces``: (node ids (k,), unit normals (k, 2), tractions sigma . n (k, 2)) imposed on the recovered
    stress at those nodes (the defect faces: :func:`face_tractions`)."""
    tri = np.asarray(tri, dtype=np.int64)
    s, area = p1_stress(nodes, tri, u, lam, mu)
    star = recovered_stress(tri, s, area, nodes.shape[1])
    if faces is not None and len(faces[0]):
        ids = np.asarray(faces[0], dtype=np.int64)
        star[ids] = impose_traction(star[ids], faces[1], faces[2])
    corner = star[tri.T]                                               # (nt, 3, 3): per triangle, per vertex
    mids = 0.5 * (corner + corner[:, [1, 2, 0]])                       # edge midpoints
    dens = _energy_density(mids - s[:, None, :], lam, mu)              # (nt, 3)
    eta2 = area / 3.0 * dens.sum(axis=1)
    return Estimate(eta2=eta2, energy2=area * _energy_density(s, lam, mu), area=area)


def face_tractions(interface, nodal_u: np.ndarray,
                   pressure: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(node ids, normals, tractions) of both faces of a 2D defect interface (``QP.interface``): at node j
    of either face sigma . nu = [u]_j / delta_j - p_j nu_j (``[u] = u+ - u-``; ``pressure`` p (m,) or None:
    no contact term; ``interface.delta`` None: no interface term)."""
    up, lo, nrm = interface.upper, interface.lower, interface.normals
    t = np.zeros_like(nrm, dtype=float)
    if interface.delta is not None:
        t += (nodal_u[up] - nodal_u[lo]) / np.asarray(interface.delta, dtype=float)[:, None]
    if pressure is not None:
        t -= np.asarray(pressure, dtype=float)[:, None] * nrm
    return np.r_[up, lo], np.vstack([nrm, nrm]), np.vstack([t, t])


def optimal_sizes(est: Estimate, target: float, max_elements: float, order: float = 1.0,
                  max_size: float = np.inf, steps: tuple[float, float] = (1 / 8, 2.0),
                  min_size: float = 0.0) -> np.ndarray:
    """Per-triangle sizes of the next mesh (the optimal-mesh rule, module docstring).

    ``target``: the relative error wanted, in (0, 1); ``max_elements``: the budget of triangles (the sizes
    are scaled up when sum (h_T / h_new)^dim exceeds it); ``order`` p: the error's order in h; ``steps``: the
    smallest and largest ratio h_new / h_T in one step; ``max_size``: no size above it; ``min_size``: none below
    it (the mesher's resolution: at a crack tip the rule keeps asking for smaller elements)."""
    h = est.sizes
    allowed2 = target ** 2 * (est.energy2.sum() + est.eta2.sum()) / est.eta2.size
    with np.errstate(divide="ignore"):
        ratio = (allowed2 / np.maximum(est.eta2, 1e-300)) ** (0.5 / order)
    h_new = np.clip(h * np.clip(ratio, *steps), min_size, max_size)
    count = float(np.sum((h / h_new) ** est.dim))
    if count > max_elements:
        h_new = h_new * (count / max_elements) ** (1.0 / est.dim)
    return h_new


def equidistributed_sizes(est: Estimate, target: float, max_elements: float, order: float = 1.0,
                          max_size: float = np.inf, steps: tuple[float, float] = (1 / 8, 2.0),
                          min_size: float = 0.0) -> np.ndarray:
    """Per-element sizes of the next mesh that equidistribute the predicted error (arguments as
    :func:`optimal_sizes`).

    The error density of element T is ``c_T = eta_T^2 / h_T^(2p + d)`` (eta_T^2 ~ c h^(2p) |T|, |T| ~ h^d);
    the mesh of N elements minimizing sum c_T h'^(2p) |T| has ``h'_T = lam c_T^(-1 / (2p + d))``, i.e.
    ``h'_T = lam h_T eta_T^(-2 / (2p + d))`` (exponent 0.4 in 3D, 0.5 in 2D for P1: the rule of
    :func:`optimal_sizes`, exponent 1 / p, over-refines where eta_T is large and coarsens elsewhere, one step
    over-correcting the next). ``lam``: the largest of the one meeting ``target`` (predicted error
    sum c_T h'_T^(2p) h_T^d) and the one meeting ``max_elements`` (count sum (h_T / h'_T)^d)."""
    h, d = est.sizes, est.dim
    eta2 = np.maximum(est.eta2, 1e-300)
    shape = h * eta2 ** (-1.0 / (2 * order + d))                         # h'_T at lam = 1
    allowed2 = target ** 2 * (est.energy2.sum() + est.eta2.sum())
    predicted2 = float(np.sum(eta2 * (shape / h) ** (2 * order)))       # c_T h'^(2p) h_T^d at lam = 1
    lam_target = (allowed2 / predicted2) ** (0.5 / order)
    lam_budget = (float(np.sum((h / shape) ** d)) / max_elements) ** (1.0 / d)
    h_new = np.maximum(lam_target, lam_budget) * shape
    return np.clip(np.clip(h_new / h, *steps) * h, min_size, max_size)


def nodal_u(qp, x: np.ndarray) -> np.ndarray:
    """Displacement (n, 2) of every node of ``qp.geometry`` from the free unknowns ``x`` (fixed ones 0)."""
    nd = qp.geometry.node_dofs
    x = np.asarray(x, dtype=float) + (0.0 if qp.shift is None else qp.shift.x)
    u = np.zeros(nd.shape[::-1])
    mask = nd >= 0
    u.T[mask] = x[nd[mask]]
    return u


def estimate(qp, x: np.ndarray, multipliers: np.ndarray | None = None) -> Estimate:
    """:func:`zz_estimate` (P2 triangles: :func:`dualfem.numerics.estimator_p2.zz_estimate_p2`; 3D P1:
    :func:`zz_estimate3`) of a QP's answer (``qp.geometry``, ``qp.material``, ``qp.interface``):
    the defect faces' tractions from the interface term and, with ``multipliers``, the contact pressure."""
    from dualfem.core.elasticity import lame

    g, mat = qp.geometry, qp.material
    if g is not None and g.element != "P1" and g.dim != 2:   # first: a 3D P2 QP's cells are quadratic (10 rows)
        raise InputError(f"the estimator takes P1 (2D, 3D) and P2 triangles; this QP has element = {g.element!r} in "
                         f"{g.dim}D")
    if g is None or mat is None or g.cells.shape[0] != g.dim + 1:
        raise ValueError("the estimator needs a P1 triangle or tetrahedron mesh and the material (qp.geometry, "
                         "qp.material)")
    u = nodal_u(qp, x)
    if g.dim == 3:
        lam3, mu3 = _lame3(mat.E, mat.nu)
        faces3 = None
        if qp.interface is not None and qp.m:
            faces3 = face_tractions(qp.interface, u, None if multipliers is None else qp.pressure(multipliers))
        return zz_estimate3(g.nodes, g.cells, u, lam3, mu3, faces3)
    lam, mu = lame(mat.E, mat.nu, mat.plane)
    faces = None
    if qp.interface is not None and qp.interface.dim == 2 and qp.m:
        faces = face_tractions(qp.interface, u, None if multipliers is None else qp.pressure(multipliers))
    if g.element != "P1":                    # quadratic triangles: numerics/estimator_p2.py
        from .estimator_p2 import zz_estimate_p2

        return zz_estimate_p2(g.nodes, g.cells, u, lam, mu, faces)
    return zz_estimate(g.nodes, g.cells, u, lam, mu, faces)


def _lame3(E: float, nu: float) -> tuple[float, float]:
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


#: the 4-point rule on a tetrahedron, exact for quadratics: barycentric (A, B, B, B) and its permutations
_A, _B = 0.5854101966249685, 0.1381966011250105


def _full_energy(s: np.ndarray, lam: float, mu: float) -> np.ndarray:
    """sigma : C^-1 sigma for full stress tensors (..., d, d) of isotropic elasticity in d dimensions."""
    d = s.shape[-1]
    tr = np.trace(s, axis1=-2, axis2=-1)
    return (np.sum(s * s, axis=(-2, -1)) - lam / (d * lam + 2 * mu) * tr ** 2) / (2 * mu)


def zz_estimate3(nodes: np.ndarray, tets: np.ndarray, u: np.ndarray, lam: float, mu: float,
                 faces: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> Estimate:
    """:func:`zz_estimate` on P1 tetrahedra (``nodes`` (3, n), ``tets`` (4, nt), ``u`` (n, 3)): the recovered
    stress the volume-weighted nodal mean, the defect faces' tractions imposed, the indicator integrated by
    the 4-point rule (exact: the integrand is quadratic); ``area`` holds the volumes."""
    from .p1 import tet_gradients

    tets = np.asarray(tets, dtype=np.int64)
    g, vol = tet_gradients(nodes, tets)
    vol = np.abs(vol)
    du = np.einsum("tic,idt->tcd", u[tets.T], g)                        # du[t, c, d] = d u_c / d x_d
    eps = 0.5 * (du + du.transpose(0, 2, 1))
    sig = 2 * mu * eps + lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(3)
    n_nodes = nodes.shape[1]
    w = np.bincount(tets.ravel(), weights=np.tile(vol, 4), minlength=n_nodes)
    flat = sig.reshape(-1, 9)
    star = np.stack([np.bincount(tets.ravel(), weights=np.tile(vol * flat[:, k], 4), minlength=n_nodes)
                     for k in range(9)], axis=1) / np.where(w > 0, w, 1.0)[:, None]
    star = star.reshape(-1, 3, 3)
    if faces is not None and len(faces[0]):
        ids = np.asarray(faces[0], dtype=np.int64)
        n = np.asarray(faces[1], dtype=float)
        r = np.asarray(faces[2], dtype=float) - np.einsum("kij,kj->ki", star[ids], n)
        rn = np.sum(r * n, axis=1)
        star[ids] += (r[:, :, None] * n[:, None, :] + n[:, :, None] * r[:, None, :]
                      - rn[:, None, None] * n[:, :, None] * n[:, None, :])
    corner = star[tets.T]                                               # (nt, 4, 3, 3)
    eta2 = np.zeros(tets.shape[1])
    for q in range(4):
        bary = np.full(4, _B)
        bary[q] = _A
        at_q = np.einsum("v,tvij->tij", bary, corner)
        eta2 += vol / 4.0 * _full_energy(at_q - sig, lam, mu)
    return Estimate(eta2=eta2, energy2=vol * _full_energy(sig, lam, mu), area=vol, dim=3)
