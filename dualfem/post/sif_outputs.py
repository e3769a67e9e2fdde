"""Stress intensity factors as outputs: the method choice, the ``sif`` record of ``dualfem solve --json`` and the
VTU point fields of 3D fronts (the figure of K along a front: benchmarks/sif_report.py).

``method="auto"`` (and ``"interaction"``): the interaction integral, at 2D tips (:mod:`dualfem.post.sif_integral`)
and along 3D fronts (:mod:`dualfem.post.sif_integral3d`), the more accurate on P1 meshes; ``"fit"`` and
``"extrapolate"``: the displacement correlation (:mod:`dualfem.post.sif`). On a ``P2`` or ``P2-quarter-point`` QP
``"auto"`` (and ``"series"``) is the two-term Williams fit of the jumps, ``"quarter-point"`` the classic
quarter-point correlation (:mod:`dualfem.post.sif_quarter`); the other methods need P1.
"""
from __future__ import annotations

import numpy as np

from dualfem.core.errors import InputError
from dualfem.post.sif import METHODS, StressIntensity, correlation
from dualfem.post.sif_integral import interaction
from dualfem.post.sif_integral3d import interaction3d
from dualfem.post.sif_quarter import P2_ELEMENTS, quarter_point, series_fit

#: every method :func:`stress_intensity` accepts
ALL_METHODS = ("auto", "interaction", *METHODS, "series", "quarter-point")


def stress_intensity(qp, x, method: str = "auto", **options) -> StressIntensity:
    """K_I, K_II (, K_III) at every tip or front node of the QP's defects from the unknowns ``x`` (module
    docstring; ``options``: ``r_out`` of the interaction integral, ``rings`` of the correlation)."""
    if method not in ALL_METHODS:
        raise InputError(f"method must be one of {', '.join(ALL_METHODS)}, got {method!r}")
    g = getattr(qp, "geometry", None)
    if method == "quarter-point":
        return quarter_point(qp, x)
    dim = getattr(getattr(qp, "interface", None), "dim", None)
    if method == "auto" and g is not None and g.element == "P2" and dim == 3:
        return interaction3d(qp, x, **options)       # quadratic tetrahedra: the domain integral at 4 points each
    if method == "series" or (method == "auto" and g is not None and g.element in P2_ELEMENTS):
        return series_fit(qp, x, **options)
    if method in ("auto", "interaction"):
        return (interaction3d if dim == 3 else interaction)(qp, x, **options)
    return correlation(qp, x, method, **options)


def has_fronts(qp) -> bool:
    """Whether the QP has what stress intensity factors need: interface with tips or fronts, mesh, material."""
    it = getattr(qp, "interface", None)
    return it is not None and it.front.size > 0 and getattr(qp, "geometry", None) is not None \
        and getattr(qp, "material", None) is not None and qp.shift is None


def sif_result(qp, sol) -> tuple[StressIntensity | None, dict | None]:
    """(the factors, the ``sif`` field of ``dualfem solve --sif --json``: :meth:`StressIntensity.to_json` per tip
    or front node, or ``{"error": ...}`` when they cannot be computed: the solve's answer stands, the record says
    why); (None, None) when the QP has no front or there is no answer."""
    if sol.x is None or not has_fronts(qp):
        return None, None
    try:
        sif = stress_intensity(qp, sol.x)
        return sif, sif.to_json()
    except InputError as e:
        return None, {"error": str(e)}
    except (ValueError, IndexError, ArithmeticError, np.linalg.LinAlgError) as e:     # a geometry it does not handle
        return None, {"error": f"stress intensity factors failed on this geometry ({type(e).__name__}: {e})"}


def sif_record(qp, sol) -> dict | None:
    """The ``sif`` field alone (:func:`sif_result`)."""
    return sif_result(qp, sol)[1]


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


def summary_line(sif: dict) -> str:
    """One line of ``dualfem solve --sif``'s summary from the ``sif`` record (:func:`sif_result`): each 2D tip's
    K_I, K_II; a 3D front's ranges."""
    if "error" in sif:
        return f"stress intensity factors: not computed ({sif['error']})"
    modes = [k for k in ("K_I", "K_II", "K_III") if k in sif]
    if "K_III" not in sif:
        return f"stress intensity factors ({sif['method']}): " + "; ".join(
            f"tip {i}: " + " ".join(f"{k} {sif[k][i]:.4g}" for k in modes) for i in range(len(sif["K_I"])))
    return f"stress intensity factors ({sif['method']}, {len(sif['K_I'])} front nodes): " + "  ".join(
        f"{k} in [{min(sif[k]):.4g}, {max(sif[k]):.4g}]" for k in modes)
