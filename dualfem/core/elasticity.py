"""Isotropic linear elasticity in 2D: the material law shared by problems and post-processing."""
from __future__ import annotations

#: the 2D reductions of 3D elasticity (``plane = "strain"`` is dualfem's default)
PLANES = ("strain", "stress")


def lame(E: float, nu: float, plane: str) -> tuple[float, float]:
    """Lame parameters (lambda, mu) of the 2D model, in the units of E.

    Plane strain uses the 3D values; plane stress uses lambda* = 2 lambda mu / (lambda + 2 mu).
    """
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    if plane == "stress":
        lam = 2 * lam * mu / (lam + 2 * mu)
    return lam, mu
