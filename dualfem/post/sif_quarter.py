"""Stress intensity factors at 2D tips of quadratic (``element = "P2"``, ``"P2-quarter-point"``) meshes from the jumps.

``series_fit`` (``method="series"``, the default on P2): the jumps in the tip frame at the crack pairs within
``reach`` x the defect's length of the tip (default 0.2) fitted by least squares with the first two terms of
the Williams series of a jump, ``[u](r) = c1 sqrt(r) + c3 r^(3/2)`` (a jump holds only half-integer powers of
r), and K read from c1 as in :mod:`dualfem.post.sif` (``K = G / (kappa + 1) sqrt(2 pi) c1``).

``quarter_point`` (``method="quarter-point"``, P2-quarter-point only): the classic quarter-point displacement
correlation (Shih, de Lorenzi and German 1976) from the two crack pairs of the tip's crack edge.

On a quarter-point crack edge of length L (tip A, mid-edge node B at L/4 from the tip, vertex C at L) the
isoparametric map makes the displacement ``u(r) = u_A + (4 u_B - u_C - 3 u_A) sqrt(r/L) + (2 u_A - 4 u_B + 2 u_C) r/L``
along the edge; the tip is single, so the jump ``[u](r)`` has the sqrt(r) coefficient ``(4 [u]_B - [u]_C) / sqrt(L)``.
Matched with the Williams jumps of :mod:`dualfem.post.sif` (``[u . e2] = (kappa + 1)/G K_I sqrt(r / (2 pi))``,
``[u . e1]`` likewise with K_II)::

    K = G / (kappa + 1) sqrt(2 pi / L) (4 [u](L/4) - [u](L))      (plane strain: G / (kappa + 1) = E' / 8)

Both in the tip frame (e1: toward the tip, e2: the upper face's normal), with the conventions and signs of
:func:`dualfem.post.sif.correlation`; ``radius``: the reach (series) or L (quarter-point). Measured on the
Griffith crack (reports/accuracy.md): the quarter-point formula is 4-9 % off (the solution's error at the quarter
node is amplified four times; on the exact jumps its truncation is + L / (8 a)), the series fit within about 0.5 %
on the same meshes.
"""
from __future__ import annotations

import numpy as np

from dualfem.core.errors import InputError
from dualfem.post.sif import StressIntensity, check_x, kolosov, parts, tip_frames_2d

#: the nearest pair must lie at L/4 of the tip's crack edge, within this relative tolerance
QUARTER_RTOL = 1e-6
#: the quadratic elements these methods accept
P2_ELEMENTS = ("P2", "P2-quarter-point")


def _setup(qp, x, elements):
    it, g, mat = parts(qp, elements=elements)
    if it.dim != 2:
        raise InputError("stress intensity factors on quadratic elements are 2D only")
    x = check_x(qp, x)
    G = mat.E / (2 * (1 + mat.nu))
    coef = G / (kolosov(mat.nu, mat.plane, 2) + 1) * np.sqrt(2 * np.pi)
    frames, tip_rows = tip_frames_2d(it, g.nodes)
    return it, g.nodes, coef, x[it.plus_dofs] - x[it.minus_dofs], frames, tip_rows


def _tip_jumps(it, pts, jump, tip, rows, F):
    """(distances r (p,), jumps (p, 2) in the tip frame F) of the crack pairs ``rows`` of a tip."""
    r = np.hypot(*(pts[:, it.lower[rows]] - pts[:, tip][:, None]))
    side = np.sign(it.normals[rows] @ F[1])
    return r, side[:, None] * (jump[rows] @ F.T)


def series_fit(qp, x, reach: float = 0.2) -> StressIntensity:
    """K_I, K_II at every 2D tip of a P2 QP: the two-term Williams fit of the jumps within ``reach`` x the
    defect's length of the tip (module docstring). InputError for a P1 QP, a reach outside (0, 0.5] or fewer
    than 3 pairs within reach."""
    if not (isinstance(reach, (int, float)) and 0 < reach <= 0.5):
        raise InputError(f"reach must be a number in (0, 0.5] (a fraction of the defect's length), got {reach!r}")
    it, pts, coef, jump, frames, tip_rows = _setup(qp, x, P2_ELEMENTS)
    K, radius = np.zeros((it.front.size, 2)), np.zeros(it.front.size)
    for k, tip in enumerate(it.front):
        d = it.front_id[k]
        ends = pts[:, it.front[it.front_id == d]]
        length = float(np.hypot(*(ends[:, -1] - ends[:, 0])))
        rows = tip_rows[k]
        r, J = _tip_jumps(it, pts, jump, tip, rows, frames[k])
        use = r <= reach * length * (1 + 1e-9)
        if use.sum() < 3:
            raise InputError(f"tip {k} (node {int(tip)}): {int(use.sum())} crack pairs within reach = {reach:g} of "
                             f"the defect's length; refine the mesh at the tip or raise reach")
        A = np.stack([np.sqrt(r[use]), r[use] ** 1.5], axis=1)
        K[k] = coef * np.linalg.lstsq(A, J[use], rcond=None)[0][0]
        radius[k] = reach * length
    return StressIntensity(2, it.front.copy(), pts[:, it.front].T.copy(), it.front_id.copy(), K[:, 1].copy(),
                           K[:, 0].copy(), None, frames, "series", radius)


def quarter_point(qp, x) -> StressIntensity:
    """K_I, K_II at every 2D tip of a ``P2-quarter-point`` QP from its unknowns ``x`` (module docstring).
    InputError for another element or a tip whose nearest crack pairs are not at L/4 and L."""
    it, pts, coef, jump, frames, tip_rows = _setup(qp, x, ("P2-quarter-point",))
    K, radius = np.zeros((it.front.size, 2)), np.zeros(it.front.size)
    for k, tip in enumerate(it.front):
        rows, F = tip_rows[k], frames[k]
        if rows.size < 2:
            raise InputError(f"tip {k} (node {int(tip)}) has fewer than 2 crack pairs behind it")
        r, J = _tip_jumps(it, pts, jump, tip, rows[:2], F)
        if abs(r[0] - r[1] / 4) > QUARTER_RTOL * r[1]:
            raise InputError(f"tip {k} (node {int(tip)}): its nearest crack pair is at {r[0]:.4g}, not at a quarter "
                             f"of its crack edge ({r[1]:.4g} / 4): not a quarter-point edge")
        K[k] = coef * (4 * J[0] - J[1]) / np.sqrt(r[1])
        radius[k] = r[1]
    return StressIntensity(2, it.front.copy(), pts[:, it.front].T.copy(), it.front_id.copy(), K[:, 1].copy(),
                           K[:, 0].copy(), None, frames, "quarter-point", radius)
