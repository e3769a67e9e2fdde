"""Friction against its closed forms: the cases of the validation tests and of the friction report.

Every case builds a scene with the friction keys (docs/friction.md), solves it through the runner (certified like
any answer) and measures the answer against a closed form. E = 1000, nu = 0.3, delta = 1e3 (a free interface:
only friction holds the faces), lengths in the body's unit.

* :func:`inclined_2d`: a closed straight crack of half-length a at angle ``angle_deg`` in the unit plate (gmsh),
  under the remote stress S (compression); on the crack plane the contact pressure ``sigma_n = -n.S.n`` and the
  shear ``tau = t.S.n``; the slip (plane strain) ``4 (1 - nu^2) (|tau| - tau_c)_+ / E sqrt(a^2 - x^2)`` with
  ``tau_c = g`` (Tresca) or ``mu_f sigma_n`` (Coulomb); stick (no slip at all) when ``|tau| <= tau_c``.
* :func:`penny_3d`: the library's ``penny`` scene (a disk of radius 1 in a cube of side 10) under compression
  ``sigma_n`` and shear ``tau`` (sigma_xz); Segedin's slip along x with the effective shear,
  ``16 (1 - nu^2) (tau - tau_c)_+ / (pi (2 - nu) E) sqrt(a^2 - r^2)``.
* :func:`stuck_2d`: a crack held by a large threshold against the uncracked body (structured grid: the same
  mesh without the cut): the displacements agree to rounding.

Errors are relative L2 over the inner part (|x| <= 0.8 a, r <= 0.8 a) with the nodal weights. The closed forms
are for an infinite body: the plate (side 20 a) and the cube (side 10 a) leave a finite-size effect of ~1-2 %.
"""
from __future__ import annotations

import time

import numpy as np

from dualfem.core.scene import load_scene
from dualfem.experiments.runner import run

E, NU, DELTA = 1000.0, 0.3, 1e3
#: the 2D remote stress: compression 1 across y, 0.2 across x (the crack's angle resolves it)
STRESS_2D = ((-0.2, 0.0), (0.0, -1.0))
#: the penny: compression and shear on the crack plane (sigma_zz = -SIGMA_N, sigma_xz = TAU)
SIGMA_N, TAU = 1.0, 0.5


def _keys(law: str, value: float) -> dict:
    if law == "none":
        return {}
    return {"friction": law, ("friction_bound" if law == "tresca" else "friction_coefficient"): float(value)}


def _l2(w: np.ndarray, value: np.ndarray, exact: np.ndarray, inner: np.ndarray) -> float:
    den = float(np.sum(w[inner] * exact[inner] ** 2))
    num = float(np.sum(w[inner] * (value[inner] - exact[inner]) ** 2))
    return float(np.sqrt(num / den)) if den > 0 else float("nan")


def resolved(angle_deg: float, stress=STRESS_2D) -> tuple[float, float]:
    """(contact pressure sigma_n = -n.S.n, shear tau = t.S.n) on a crack at ``angle_deg`` (t its direction)."""
    th = np.radians(angle_deg)
    t, n = np.array([np.cos(th), np.sin(th)]), np.array([-np.sin(th), np.cos(th)])
    S = np.asarray(stress, float)
    return float(-n @ S @ n), float(t @ S @ n)


def critical(law: str, value: float, sigma_n: float) -> float:
    """The shear the faces carry before slipping: g (Tresca), mu_f sigma_n (Coulomb), 0 (none)."""
    return float(value) if law == "tresca" else float(value) * sigma_n if law == "coulomb" else 0.0


def _outcome(qp, sol, t0: float) -> dict:
    cert = sol.info.get("certificate", {}) if sol.info else {}
    return {"n": qp.n, "m": qp.m, "status": str(sol.status), "seconds": time.perf_counter() - t0,
            "iterations": dict(sol.iterations or {}), "certified": cert.get("value")}


def inclined_2d(angle_deg: float, law: str, value: float, mesh_size: float = 0.05, tip_size: float = 0.004,
                a: float = 0.05, solver: str = "clarabel") -> dict:
    """The 2D inclined closed crack (module docstring): slip error, stick detection, the answer's facts."""
    th = np.radians(angle_deg)
    d = a * np.array([np.cos(th), np.sin(th)])
    t0 = time.perf_counter()
    qp = load_scene("f2", {"mesh": "gmsh", "mesh_size": mesh_size, "tip_size": tip_size, "E": E, "nu": NU,
                                    "delta": DELTA, "remote_stress": [list(r) for r in STRESS_2D],
                                    "defects": [{"points": [(0.5 - d).tolist(), (0.5 + d).tolist()]}],
                                    **_keys(law, value)}).build()
    sol = run(solver, qp)
    out = {"angle": angle_deg, "law": law, "value": value, "mesh_size": mesh_size, "tip_size": tip_size,
           **_outcome(qp, sol, t0)}
    sigma_n, tau = resolved(angle_deg)
    tau_c = critical(law, value, sigma_n)
    out.update(sigma_n=sigma_n, tau=tau, tau_c=tau_c)
    if sol.x is None:
        return out
    normal, tangential = qp.interface.jumps(sol.x)
    x = qp.interface.s - a
    slip = np.abs(tangential[:, 0])
    exact = 4 * (1 - NU ** 2) * max(abs(tau) - tau_c, 0.0) / E * np.sqrt(np.maximum(a * a - x * x, 0.0))
    out.update(x=x.tolist(), slip=slip.tolist(), exact=exact.tolist(),
               pressure=(sol.multipliers[:qp.m] / qp.weights).tolist(),
               closure=float(np.abs(normal).max() / max(np.abs(sol.x).max(), 1e-300)),
               max_slip=float(slip.max(initial=0.0)), scale=float(np.abs(sol.x).max()))
    inner = np.abs(x) <= 0.8 * a
    if exact.max() > 0:
        out["error"] = _l2(qp.weights, slip, exact, inner)
    # the nodal contact pressure against sigma_n (it feeds Coulomb's threshold mu_f lambda_j)
    out["pressure_error"] = _l2(qp.weights, np.asarray(out["pressure"]), np.full(qp.m, sigma_n), inner)
    return out


def penny_3d(law: str, value: float, mesh_size: float = 2.0, tip_size: float = 0.25, surface_size: float = 0.0,
             solver: str = "clarabel") -> dict:
    """The penny under compression and shear (module docstring): Segedin's slip error, the answer's facts."""
    stress = [[0.0, 0.0, TAU], [0.0, 0.0, 0.0], [TAU, 0.0, -SIGMA_N]]
    t0 = time.perf_counter()
    qp = load_scene("penny", {"mesh_size": mesh_size, "tip_size": tip_size, "surface_size": surface_size, "E": E,
                              "nu": NU, "delta": DELTA, "remote_stress": stress, **_keys(law, value)}).build()
    sol = run(solver, qp)
    out = {"law": law, "value": value, "mesh_size": mesh_size, "tip_size": tip_size, "surface_size": surface_size,
           **_outcome(qp, sol, t0)}
    tau_c = critical(law, value, SIGMA_N)
    out.update(sigma_n=SIGMA_N, tau=TAU, tau_c=tau_c)
    if sol.x is None:
        return out
    nodes, nd = qp.geometry.nodes, qp.geometry.node_dofs
    lo, up = qp.interface.lower, qp.interface.upper
    px, py = nodes[0, lo] - 5.0, nodes[1, lo] - 5.0
    r = np.hypot(px, py)
    slip = sol.x[nd[0, up]] - sol.x[nd[0, lo]]
    across = sol.x[nd[1, up]] - sol.x[nd[1, lo]]
    exact = 16 * (1 - NU ** 2) * max(TAU - tau_c, 0.0) / (np.pi * (2 - NU) * E) * np.sqrt(np.maximum(1 - r * r, 0))
    out.update(px=px.tolist(), py=py.tolist(), slip=slip.tolist(), exact=exact.tolist(),
               max_slip=float(np.abs(slip).max(initial=0.0)), max_across=float(np.abs(across).max(initial=0.0)),
               scale=float(np.abs(sol.x).max()))
    if exact.max() > 0:
        out["error"] = _l2(qp.weights, slip, exact, r <= 0.8)
    return out


def stuck_2d(N: int = 16, bound: float = 10.0, solver: str = "clarabel") -> dict:
    """A horizontal crack under compression and shear held by the threshold ``bound`` (> the shear 0.3: stick),
    against the uncracked body on the same structured grid: the largest difference of the nodal displacements
    relative to the largest displacement, and the largest slip."""
    keys = {"N": N, "E": E, "nu": NU, "delta": DELTA, "remote_stress": [[-1.0, 0.3], [0.3, -1.0]]}
    cracked = load_scene("f2", {**keys, "friction": "tresca", "friction_bound": bound}).build()
    whole = load_scene("f2", {**keys, "defects": []}).build()
    a, b = run(solver, cracked), run(solver, whole)

    def nodal(qp, x):
        nd = qp.geometry.node_dofs[:, :whole.geometry.node_dofs.shape[1]]
        return np.where(nd >= 0, x[np.maximum(nd, 0)], 0.0)

    ua, ub = nodal(cracked, a.x), nodal(whole, b.x)
    _, tangential = cracked.interface.jumps(a.x)
    return {"status": str(a.status), "difference": float(np.abs(ua - ub).max() / np.abs(ub).max()),
            "max_slip": float(np.abs(tangential).max() / np.abs(ub).max()),
            "stick_nodes": int(np.sum(np.abs(tangential[:, 0]) <= 1e-12 * np.abs(ub).max())), "m": cracked.m}


# ------------------------------------------------------------------------------------------- the study
#: the report's defaults: 2D mesh levels (mesh_size, tip_size), crack angles (degrees) and (law, value) cases
LEVELS_2D = ((0.02, 0.002), (0.01, 0.001), (0.005, 0.0005))
ANGLES = (20.0, 30.0, 60.0)
CASES_2D = (("none", 0.0), ("tresca", 0.1), ("coulomb", 0.2), ("coulomb", 0.5))
#: 3D penny levels (mesh_size, tip_size) and cases
LEVELS_3D = ((2.0, 0.25), (1.5, 0.15))
CASES_3D = (("none", 0.0), ("tresca", 0.2), ("tresca", 0.6), ("coulomb", 0.2))


def compare_row(name: str, qp, label: str) -> dict:
    """One solver on one frictional QP: status (the skip reason when it does not take the law), times, counters
    and the certified error."""
    sol = run(name, qp)
    cert = sol.info.get("certificate", {}) if sol.info else {}
    return {"solver": name, "case": label, "status": str(sol.status), "message": sol.message,
            "setup_s": sol.time_s.get("setup"), "solve_s": sol.time_s.get("solve"),
            "iterations": {k: v for k, v in (sol.iterations or {}).items() if isinstance(v, (int, float))},
            "certified": cert.get("value")}


def _compare(solvers, fine2, fine3, progress) -> list[dict]:
    """Every solver of ``solvers`` on the 2D crack at 30 degrees (the given level) and the penny (coarsest level),
    Tresca and Coulomb."""
    rows = []
    th = np.radians(30.0)
    d = 0.05 * np.array([np.cos(th), np.sin(th)])
    base2 = {"mesh": "gmsh", "mesh_size": fine2[0], "tip_size": fine2[1], "E": E, "nu": NU, "delta": DELTA,
             "remote_stress": [list(r) for r in STRESS_2D], "defects": [{"points": [(0.5 - d).tolist(),
                                                                                  (0.5 + d).tolist()]}]}
    base3 = {"mesh_size": fine3[0], "tip_size": fine3[1], "E": E, "nu": NU, "delta": DELTA,
             "remote_stress": [[0.0, 0.0, TAU], [0.0, 0.0, 0.0], [TAU, 0.0, -SIGMA_N]]}
    for label, scene, keys in (("2D tresca g=0.1", "f2", {**base2, **_keys("tresca", 0.1)}),
                               ("2D coulomb mu_f=0.2", "f2", {**base2, **_keys("coulomb", 0.2)}),
                               ("3D tresca g=0.2", "penny", {**base3, **_keys("tresca", 0.2)}),
                               ("3D coulomb mu_f=0.2", "penny", {**base3, **_keys("coulomb", 0.2)})):
        for name in solvers:          # a fresh QP each: no factorization of one solver's run serves the next
            rows.append(compare_row(name, load_scene(scene, keys).build(), label))
            progress(f"compare {label} {name}: {rows[-1]['status']}")
    return rows


def study(levels_2d=LEVELS_2D, angles=ANGLES, cases_2d=CASES_2D, levels_3d=LEVELS_3D, cases_3d=CASES_3D,
          solver: str = "clarabel", solvers=(), progress=None, coulomb_levels: int | None = None,
          resume: dict | None = None) -> dict:
    """Every case of the report (JSON-able): ``inclined`` (2D rows), ``penny`` (3D rows), ``stuck``, and
    ``compare`` (``solvers`` on four frictional QPs; empty when none is given). ``solver`` solves the
    validation cases (its certified answers are what is compared with the closed forms); ``coulomb_levels``:
    the 2D Coulomb cases run on that many of the coarsest levels only (a fixed point of several solves per case;
    None: all levels); ``resume``: a study stored earlier whose rows of the same case, level and solver are kept
    (not solved again) unless they were skipped."""
    say = progress or (lambda m: None)
    kept = _kept(resume, solver)
    out: dict = {"solver": solver, "E": E, "nu": NU, "delta": DELTA, "stress_2d": [list(r) for r in STRESS_2D],
                 "sigma_n_3d": SIGMA_N, "tau_3d": TAU, "inclined": [], "penny": [],
                 "levels_2d": [list(lv) for lv in levels_2d], "levels_3d": [list(lv) for lv in levels_3d]}
    for k, (h, tip) in enumerate(levels_2d):
        for angle in angles:
            for law, value in cases_2d:
                if law == "coulomb" and coulomb_levels is not None and k >= coulomb_levels:
                    continue
                row = kept.get(("2d", angle, law, value, h, tip)) or \
                    inclined_2d(angle, law, value, h, tip, solver=solver)
                out["inclined"].append(row)
                say(f"2D {angle:g} deg {law} {value:g} tip {tip:g}: {row['status']} {row.get('error', '-')}")
    for h, tip in levels_3d:
        for law, value in cases_3d:
            row = kept.get(("3d", law, value, h, tip)) or penny_3d(law, value, h, tip, solver=solver)
            out["penny"].append(row)
            say(f"3D {law} {value:g} mesh {h:g}/{tip:g}: {row['status']} {row.get('error', '-')}")
    out["stuck"] = kept.get("stuck") or stuck_2d(solver=solver)
    out["compare"] = compare(out, solvers, say) if solvers else []
    return out


def _kept(resume: dict | None, solver: str) -> dict:
    """The rows of a stored study to keep, by case key (same solver; skipped rows are solved again)."""
    if not resume or resume.get("solver") != solver:
        return {}
    kept: dict = {}
    for r in resume.get("inclined", []):
        if r.get("status") != "skipped":
            kept[("2d", r["angle"], r["law"], r["value"], r["mesh_size"], r["tip_size"])] = r
    for r in resume.get("penny", []):
        if r.get("status") != "skipped":
            kept[("3d", r["law"], r["value"], r["mesh_size"], r["tip_size"])] = r
    if resume.get("stuck", {}).get("status") == "solved":
        kept["stuck"] = resume["stuck"]
    return kept


def compare(res: dict, solvers, progress=None) -> list[dict]:
    """The ``compare`` rows of a study ``res``: ``solvers`` on the 2D crack at 30 degrees at the study's middle
    2D level (else the default's) and the penny at its coarsest 3D level."""
    levels = tuple(res.get("levels_2d") or LEVELS_2D)
    lv2 = levels[len(levels) // 2]
    lv3 = tuple(res.get("levels_3d") or LEVELS_3D)[0]
    return _compare(list(solvers), tuple(lv2), tuple(lv3), progress or (lambda m: None))
