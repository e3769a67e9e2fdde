"""The nodal contact pressure of inclined closed cracks, and what its error costs the Coulomb slip (issues 36, 38).

The pressure at defect node j is its normal multiplier over its nodal weight, ``p_j = mu_j / w_j`` (a stress: mu_j
is a force in 2D per unit thickness, w_j a length; in 3D w_j an area); Coulomb's threshold at node j is
``mu_f p_j``. Every case loads the crack by the remote stress whose traction on the crack plane is the normal
compression ``SIGMA_N`` and the shear ``TAU`` along the crack's in-plane direction e1 (the stress
``R [[0, TAU], [TAU, -SIGMA_N]] R'`` in 2D, ``R [[0, 0, TAU], [0, 0, 0], [TAU, 0, -SIGMA_N]] R'`` in 3D, R the
rotation that turns the crack by ``angle``), so the closed forms do not depend on the angle and only the mesh does:

* the contact pressure is ``SIGMA_N`` all over the crack (a straight or flat crack in an infinite body: the slip
  does not load the crack plane normally);
* the slip along e1 (plane strain 2D, half-length a): ``4 (1 - nu^2) (TAU - tau_c)_+ / E sqrt(a^2 - x^2)``;
  3D penny of radius 1 (Segedin with the effective shear): ``16 (1 - nu^2) (TAU - tau_c)_+ / (pi (2 - nu) E)
  sqrt(1 - r^2)``; ``tau_c`` = 0 (frictionless), g (Tresca), mu_f SIGMA_N (Coulomb).

2D: a crack of half-length a = 0.05 at ``angle`` degrees from x through the centre of the unit plate (gmsh, the
``f2`` scene's body with the remote stress); 3D: the library's ``penny`` scene (a disk of radius 1 in a cube of
side 10) with its normal tilted by ``angle`` from z towards x. E = 1000, nu = 0.3, delta = 1e3 (a free interface).
Errors are over the inner part (|x| <= 0.8 a, r <= 0.8), weighted by the nodal weights: the pressure's relative L2
and max errors against SIGMA_N, the slip's relative L2 error against its closed form. The body's finite size
(plate of side 20 a, cube of side 10 a) adds ~1-2 % to the slip against the infinite-body forms.

What the oscillation costs: the Coulomb slip error (threshold ``mu_f p_j`` from the computed pressure) against the
Tresca slip error with ``g = mu_f SIGMA_N`` (the exact pressure's threshold) on the same mesh.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from dualfem.core.scene import load_scene
from dualfem.experiments.runner import run

E, NU, DELTA = 1000.0, 0.3, 1e3
SIGMA_N, TAU = 1.0, 0.5
A_2D = 0.05
#: the report's defaults: angles (degrees), mesh levels (mesh_size, tip_size), Coulomb coefficients
ANGLES_2D = (20.0, 30.0, 60.0)
LEVELS_2D = ((0.02, 0.002), (0.01, 0.001), (0.005, 0.0005))
ANGLES_3D = (30.0, 45.0, 60.0)
LEVELS_3D = ((2.0, 0.25), (1.0, 0.1), (0.7, 0.07))
COEFFICIENTS = (0.2, 0.3)


@dataclass(frozen=True)
class Case:
    """One crack: ``dim`` 2 or 3, ``angle`` (degrees), the mesh level (``mesh_size``, ``tip_size``), the shear
    ``tau`` on the crack plane, the friction ``law`` ("none", "tresca", "coulomb") and its ``value`` (g or mu_f);
    ``size_growth``: gmsh's size slope away from the tips (2D only; 0.3 the scenes' default)."""

    dim: int
    angle: float
    mesh_size: float
    tip_size: float
    law: str = "none"
    value: float = 0.0
    tau: float = TAU
    size_growth: float = 0.3

    @property
    def tau_c(self) -> float:
        """The shear the faces carry before slipping: g (Tresca), mu_f SIGMA_N (Coulomb), 0 (none)."""
        return self.value if self.law == "tresca" else self.value * SIGMA_N if self.law == "coulomb" else 0.0


def frame(dim: int, angle: float) -> np.ndarray:
    """The rotation R (dim x dim) whose columns are the crack's frame: e1 (in-plane, the shear's direction), [e2,]
    then the unit "+" normal; 2D: e1 = (cos, sin); 3D: the normal (sin, 0, cos), e1 = (cos, 0, -sin)."""
    c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
    if dim == 2:
        return np.array([[c, -s], [s, c]])
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def remote_stress(dim: int, angle: float, tau: float = TAU) -> np.ndarray:
    """The remote stress with traction (-SIGMA_N normal, ``tau`` along e1) on the crack plane (module docstring)."""
    R = frame(dim, angle)
    local = np.zeros((dim, dim))
    local[-1, -1] = -SIGMA_N
    local[0, -1] = local[-1, 0] = tau
    return R @ local @ R.T


def _friction_keys(case: Case) -> dict:
    if case.law == "none":
        return {}
    key = "friction_bound" if case.law == "tresca" else "friction_coefficient"
    return {"friction": case.law, key: float(case.value)}


def build(case: Case):
    """The QP of ``case`` (module docstring)."""
    R = frame(case.dim, case.angle)
    keys = {"mesh_size": case.mesh_size, "tip_size": case.tip_size, "E": E, "nu": NU, "delta": DELTA,
            "remote_stress": remote_stress(case.dim, case.angle, case.tau).tolist(), **_friction_keys(case)}
    if case.dim == 2:
        d = A_2D * R[:, 0]
        return load_scene("f2", {"mesh": "gmsh", **keys, "size_growth": case.size_growth,
                                 "defects": [{"points": [(0.5 - d).tolist(), (0.5 + d).tolist()]}]}).build()
    return load_scene("penny", {**keys, "defects": [{"shape": "disk", "center": [5.0, 5.0, 5.0],
                                                     "normal": R[:, 2].tolist(), "radius": 1.0}]}).build()


def crack_coordinates(qp, case: Case) -> tuple[np.ndarray, np.ndarray]:
    """(signed position x along the 2D crack from its centre, or the radius r in the 3D disk's plane; the
    relative distance to the tips / front: |x| / a or r)."""
    if case.dim == 2:
        x = qp.interface.s - A_2D
        return x, np.abs(x) / A_2D
    n = frame(3, case.angle)[:, 2]
    X = qp.geometry.nodes[:, qp.interface.lower] - 5.0
    r = np.linalg.norm(X - np.outer(n, n @ X), axis=0)
    return r, r


def closed_form_slip(case: Case, rho: np.ndarray) -> np.ndarray:
    """The slip along e1 at relative distance ``rho`` from the centre (module docstring)."""
    eff = max(case.tau - case.tau_c, 0.0)
    if case.dim == 2:
        return 4 * (1 - NU ** 2) * eff / E * A_2D * np.sqrt(np.maximum(1 - rho ** 2, 0.0))
    return 16 * (1 - NU ** 2) * eff / (np.pi * (2 - NU) * E) * np.sqrt(np.maximum(1 - rho ** 2, 0.0))


def relative_l2(w: np.ndarray, value: np.ndarray, exact: np.ndarray) -> float:
    """sqrt(sum w (value - exact)^2 / sum w exact^2) (nan when the exact values vanish)."""
    den = float(np.sum(w * exact ** 2))
    return float(np.sqrt(np.sum(w * (value - exact) ** 2) / den)) if den > 0 else float("nan")


def pressure(qp, sol) -> np.ndarray:
    """The nodal contact pressure p_j = mu_j / w_j of the Signorini block (block 0), a stress."""
    return qp.pressure(np.asarray(sol.multipliers[:qp.m], dtype=float))


def slip_along(qp, sol, case: Case) -> np.ndarray:
    """The tangential jump e1 . (u^+ - u^-) at every defect node pair."""
    e1 = frame(case.dim, case.angle)[:, 0]
    nd, lo, up = qp.geometry.node_dofs, qp.interface.lower, qp.interface.upper
    jump = np.array([sol.x[nd[c, up]] - sol.x[nd[c, lo]] for c in range(case.dim)])
    return e1 @ jump


def measure(case: Case, solver: str = "pdas") -> dict:
    """Solve ``case`` with ``solver`` (certified by the runner) and measure its pressure and slip (JSON-able)."""
    t0 = time.perf_counter()
    qp = build(case)
    sol = run(solver, qp)
    cert = sol.info.get("certificate", {}) if sol.info else {}
    out = {"dim": case.dim, "angle": case.angle, "mesh_size": case.mesh_size, "tip_size": case.tip_size,
           "size_growth": case.size_growth, "law": case.law, "value": case.value, "tau": case.tau, "solver": solver,
           "n": qp.n, "m": qp.m, "status": str(sol.status), "certified": cert.get("value"),
           "seconds": time.perf_counter() - t0}
    if sol.x is None or sol.multipliers is None:
        return out
    _, rho = crack_coordinates(qp, case)
    inner = rho <= 0.8
    p, w = pressure(qp, sol), qp.weights
    out.update(rho=rho.tolist(), pressure=p.tolist(), inner=int(inner.sum()),
               pressure_l2=relative_l2(w[inner], p[inner], np.full(int(inner.sum()), SIGMA_N)),
               pressure_max=float(np.abs(p[inner] - SIGMA_N).max() / SIGMA_N),
               pressure_mean=float(np.sum(w[inner] * p[inner]) / np.sum(w[inner]) / SIGMA_N),
               pressure_outer_max=float(np.abs(p[~inner] - SIGMA_N).max(initial=0.0) / SIGMA_N),
               lost_contact=int(np.sum(p <= 1e-12 * SIGMA_N)))
    exact = closed_form_slip(case, rho)
    if exact.max() > 0:
        out["slip_l2"] = relative_l2(w[inner], slip_along(qp, sol, case)[inner], exact[inner])
    return out


def _cases(dim: int, angle: float, level, coefficients, tau: float = TAU) -> list[Case]:
    """Frictionless, then per mu_f: Coulomb mu_f and Tresca with the exact pressure's threshold mu_f SIGMA_N."""
    out = [Case(dim, angle, *level, tau=tau)]
    for mu in coefficients:
        out += [Case(dim, angle, *level, "coulomb", mu, tau), Case(dim, angle, *level, "tresca", mu * SIGMA_N, tau)]
    return out


#: the uniaxial cases: a remote uniaxial compression across the unturned crack, turned with it by ``angle``
#: puts tau / sigma_n = tan(angle) on the crack plane (here at the same sigma_n), the steepest ratio at 60 deg
UNIAXIAL_ANGLES, UNIAXIAL_COEFFICIENTS = (60.0,), (0.3,)


def uniaxial(angles=UNIAXIAL_ANGLES, levels_2d=LEVELS_2D, levels_3d=LEVELS_3D,
             coefficients=UNIAXIAL_COEFFICIENTS, solver: str = "pdas", progress=None) -> list[dict]:
    """The cases of :func:`study` with tau = tan(angle) SIGMA_N (the ratio of a uniaxial compression at ``angle``
    to the crack's normal): rows as :func:`study`'s, per-node pressure and rho kept for frictionless rows only."""
    rows = []
    for dim, levels in ((2, levels_2d), (3, levels_3d)):
        for angle in angles:
            for level in levels:
                for case in _cases(dim, angle, level, coefficients, float(np.tan(np.radians(angle))) * SIGMA_N):
                    row = measure(case, solver)
                    if case.law != "none":
                        row.pop("rho", None)
                        row.pop("pressure", None)
                    rows.append(row)
                    if progress:
                        progress(f"uniaxial {dim}D {angle:g} {level} {case.law}: {row['status']} lost "
                                 f"{row.get('lost_contact')}")
    return rows


def study(angles_2d=ANGLES_2D, levels_2d=LEVELS_2D, angles_3d=ANGLES_3D, levels_3d=LEVELS_3D,
          coefficients=COEFFICIENTS, solver: str = "pdas", check: str | None = "clarabel", progress=None) -> dict:
    """Every case of the report (JSON-able). ``rows``: each angle x level x (frictionless, Coulomb mu_f, Tresca
    mu_f SIGMA_N) solved by ``solver``; ``check``: the same frictionless and first Coulomb cases at the coarsest
    level solved by a second solver (its pressure's largest difference from ``solver``'s: the error is the
    discretization's, not a solver's); ``uniform``: tau = 0 at the coarsest level (a closed crack under uniform
    compression: the pressure must be SIGMA_N to rounding). Rows keep the per-node pressure (frictionless rows also
    the nodes' relative distance rho from the centre)."""
    say = progress or (lambda m: None)
    out: dict = {"solver": solver, "check": check, "E": E, "nu": NU, "delta": DELTA, "sigma_n": SIGMA_N, "tau": TAU,
                 "a_2d": A_2D, "coefficients": list(coefficients), "rows": [], "checks": [], "uniform": []}
    plan = [(2, a, lv) for a in angles_2d for lv in levels_2d] + [(3, a, lv) for a in angles_3d for lv in levels_3d]
    for dim, angle, level in plan:
        for case in _cases(dim, angle, level, coefficients):
            row = measure(case, solver)
            if case.law != "none":
                row.pop("rho", None)
            out["rows"].append(row)
            say(f"{dim}D {angle:g} deg {level} {case.law} {case.value:g}: {row['status']} "
                f"p {row.get('pressure_l2', float('nan')):.2e} slip {row.get('slip_l2', float('nan')):.2e}")
    coarse = [(2, a, levels_2d[0]) for a in angles_2d] + [(3, a, levels_3d[0]) for a in angles_3d]
    for dim, angle, level in coarse:
        out["uniform"].append(_strip(measure(Case(dim, angle, *level, tau=0.0), solver)))
        if check:
            for case in _cases(dim, angle, level, coefficients[:1])[:2]:
                out["checks"].append(_check(case, solver, check, out["rows"]))
                say(f"check {dim}D {angle:g} {case.law}: {out['checks'][-1]['status']}")
    return out


def _strip(row: dict) -> dict:
    return {k: v for k, v in row.items() if k not in ("rho", "pressure")}


def _check(case: Case, solver: str, check: str, rows: list[dict]) -> dict:
    """``check``'s answer on ``case`` against ``solver``'s stored row: the pressure's largest difference."""
    other = measure(case, check)
    mine = next((r for r in rows if all(r[k] == v for k, v in (("dim", case.dim), ("angle", case.angle),
                                                                ("mesh_size", case.mesh_size),
                                                                ("law", case.law), ("value", case.value)))), None)
    res = _strip(other)
    if mine is not None and "pressure" in mine and "pressure" in other:
        res["pressure_difference"] = float(np.abs(np.asarray(mine["pressure"]) - other["pressure"]).max())
    return res


#: the 2D crack refined along its length (size_growth 0.05 instead of 0.3: the crack's middle gets ~tip_size)
REFINED_2D = tuple(Case(2, 30.0, 0.02, tip, size_growth=0.05) for tip in (0.002, 0.001, 0.0005))


def refined(cases=REFINED_2D, solver: str = "pdas", progress=None) -> list[dict]:
    """Frictionless ``cases`` (rows as :func:`study`'s): does the pressure error fall when the whole crack is
    refined, not only its tips?"""
    rows = []
    for case in cases:
        rows.append(measure(case, solver))
        if progress:
            progress(f"refined {case}: {rows[-1]['status']} p {rows[-1].get('pressure_l2', float('nan')):.2e}")
    return rows
