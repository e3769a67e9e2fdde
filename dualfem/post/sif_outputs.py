"""Stress intensity factors as outputs: the method choice, the ``sif`` record of ``dualfem solve --json``, the VTU
point field of 3D fronts and the figure of K along a front against a closed form.

``method="auto"``: the interaction integral at 2D tips (:mod:`dualfem.post.sif_integral`, the more accurate on
P1 meshes), the displacement-correlation fit along 3D fronts (:mod:`dualfem.post.sif`).
"""
from __future__ import annotations

import numpy as np

from dualfem.core.errors import InputError
from dualfem.post.sif import METHODS, StressIntensity, correlation
from dualfem.post.sif_integral import interaction
from dualfem.post.style import PALETTE

#: every method :func:`stress_intensity` accepts
ALL_METHODS = ("auto", "interaction", *METHODS)


def stress_intensity(qp, x, method: str = "auto", **options) -> StressIntensity:
    """K_I, K_II (, K_III) at every tip or front node of the QP's defects from the unknowns ``x`` (module
    docstring; ``options``: ``r_out`` of the interaction integral, ``rings`` of the correlation)."""
    if method not in ALL_METHODS:
        raise InputError(f"method must be one of {', '.join(ALL_METHODS)}, got {method!r}")
    dim = getattr(getattr(qp, "interface", None), "dim", None)
    if method == "interaction" or (method == "auto" and dim == 2):
        return interaction(qp, x, **options)
    return correlation(qp, x, "fit" if method == "auto" else method, **options)


def has_fronts(qp) -> bool:
    """Whether the QP has what stress intensity factors need: interface with tips or fronts, mesh, material."""
    it = getattr(qp, "interface", None)
    return it is not None and it.front.size > 0 and getattr(qp, "geometry", None) is not None \
        and getattr(qp, "material", None) is not None and qp.shift is None


def sif_record(qp, sol) -> dict | None:
    """The ``sif`` field of ``dualfem solve --json``: :meth:`StressIntensity.to_json` per tip or front node, or
    ``{"error": ...}`` when they cannot be computed; None when the QP has no front or there is no answer."""
    if sol.x is None or not has_fronts(qp):
        return None
    try:
        return stress_intensity(qp, sol.x).to_json()
    except InputError as e:
        return {"error": str(e)}


def front_point_data(qp, sif: StressIntensity, n_points: int) -> dict[str, np.ndarray]:
    """VTU point fields ``K_I``, ``K_II``, ``K_III`` (3D): the values at the front nodes, 0 elsewhere (the VTU
    holds no NaN point field)."""
    out = {}
    for k in ("K_I", "K_II", "K_III"):
        v = getattr(sif, k)
        if v is not None:
            a = np.zeros(n_points)
            a[sif.node] = v
            out[k] = a
    return out


def front_angle(sif: StressIntensity, defect: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(order, angle in degrees) of a 3D defect's front nodes about their centroid, in the plane of the mean
    normal (e2 of the frames), angle in [0, 360) measured from the frame's first in-plane axis."""
    sel = np.flatnonzero(sif.defect == defect)
    if sel.size == 0:
        raise InputError(f"defect {defect} has no front node")
    P = sif.point[sel]
    n = sif.frame[sel, 1].mean(axis=0)
    n /= np.linalg.norm(n)
    e = np.eye(3)[np.argmin(np.abs(n))]
    a1 = np.cross(n, e)
    a1 /= np.linalg.norm(a1)
    a2 = np.cross(n, a1)
    d = P - P.mean(axis=0)
    ang = np.degrees(np.arctan2(d @ a2, d @ a1)) % 360.0
    order = np.argsort(ang)
    return sel[order], ang[order]


def sif_figure(sif: StressIntensity, exact: dict | None = None, defect: int = 0, title: str = ""):
    """Matplotlib figure of K_I, K_II, K_III along a 3D front (against the angle about its centroid) with the
    closed forms ``exact`` (a dict mode -> callable of the angle in radians) as lines; Okabe-Ito colours, one
    marker per mode."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sel, ang = front_angle(sif, defect)
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    t = np.linspace(0, 2 * np.pi, 361)
    for (mode, vals), col, mk in zip((("K_I", sif.K_I), ("K_II", sif.K_II), ("K_III", sif.K_III)), PALETTE,
                                     ("o", "s", "^")):
        if vals is None:
            continue
        ax.plot(ang, vals[sel], mk, ms=3, color=col, label=f"{mode} ({sif.method})")
        if exact and mode in exact:
            ax.plot(np.degrees(t), exact[mode](t), "-", color=col, lw=1.2, label=f"{mode} closed form")
    ax.set_xlabel("angle about the crack's centre (degrees)")
    ax.set_ylabel("K (stress x sqrt(length))")
    ax.set_xlim(0, 360)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig
