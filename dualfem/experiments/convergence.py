"""The runs behind ``reports/convergence.md``: mesh convergence of a thin-defect scene (the default scene).

Runs only; :mod:`dualfem.reports.convergence` renders. For each delta, the scene is solved on the
meshes N = 16 ... 512 and on a fine reference mesh (N = 1024 by default) with an exact solver
chosen by the one reference policy (:mod:`dualfem.experiments.reference`: its preferred order,
and the reference solve must be trusted). Every coarse solution is interpolated onto the fine
mesh (:func:`dualfem.post.fields.prolongate`: per fine triangle, from the coarse triangle
containing its centroid, hence on the correct side of the defect), and

* energy-norm error  |e|_E = sqrt(e' K_el e),  e = x_ref - I x_N,  K_el = elastic stiffness of
  the fine mesh (the H^1-type norm of Theorem 1, on the cut domain Omega_0);
* the same with the interface term, sqrt(e' K e), K = K_el + (1/delta) interface;
* L2 error  |e|_L2 from the exact P1 mass matrix of the fine mesh;

all divided by the reference's own norm (dimensionless), with observed rates log2(e_N / e_2N).
Also the energy Pi_N, the contact-zone length and the total contact force, and their differences
from the reference. :func:`study` returns all of it as one JSON-able dict (the command stores it
in reports/convergence.json). :func:`rates`, :func:`fit_rate` and :func:`triple_rates` are pure
functions of those numbers (the report uses them to render).
"""
from __future__ import annotations

import gc
import math
import time

import numpy as np

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.evaluator import kkt_residuals
from dualfem.core.scene import DEFAULT_SCENE, load_scene
from dualfem.experiments.reference import candidates, trust
from dualfem.experiments.runner import run
from dualfem.numerics.linalg import store_of
from dualfem.post.fields import contact_length, defect_fields, mass_norm2, prolongate

#: the study's defaults (``dualfem report convergence``): deltas, coarse meshes, reference mesh
DEFAULT_DELTAS = (1e-1, 1e-5, 1e-9)
DEFAULT_NS = (16, 32, 64, 128, 256, 512)
DEFAULT_REF = 1024


def level_quantities(qp, sol) -> dict:
    """Energy, contact-zone length, total contact force and contact nodes of one solution."""

    d = defect_fields(qp, sol.x)
    tol = evaluator.CONTACT_RTOL * max(np.abs(sol.x).max(initial=0.0), evaluator.TINY)
    return {
        "energy": qp.energy(sol.x),
        "contact_length": contact_length(d["s"], d["jump_normal"], tol),
        "total_force": float(np.sum(sol.multipliers)),
        "n_contact": int(evaluator.contact_set(qp, sol.x).sum()),
        "max_jump": float(np.max(d["jump_normal"])),
    }


def errors(qp_f, x_f: np.ndarray, qp_c, x_c: np.ndarray) -> dict:
    """Relative energy-norm, full-K-norm and L2 errors of a coarse solution against the fine one."""

    e = x_f - prolongate(qp_c, x_c, qp_f)
    Kel = qp_f.K_fixed
    ref_el = math.sqrt(max(x_f @ (Kel @ x_f), 0.0))
    ref_k = math.sqrt(max(x_f @ (qp_f.K @ x_f), 0.0))
    ref_l2 = math.sqrt(mass_norm2(qp_f, x_f))
    return {
        "energy_norm": math.sqrt(max(e @ (Kel @ e), 0.0)) / ref_el,
        "K_norm": math.sqrt(max(e @ (qp_f.K @ e), 0.0)) / ref_k,
        "L2": math.sqrt(mass_norm2(qp_f, e)) / ref_l2,
    }


def rates(values: list[float]) -> list[float | None]:
    """Observed rates log2(v_i / v_{i+1}) for successive halvings of h (None where undefined)."""
    out: list[float | None] = [None]
    for a, b in zip(values[:-1], values[1:]):
        out.append(math.log2(a / b) if a > 0 and b > 0 else None)
    return out


def fit_rate(hs, errs, h_ref: float) -> tuple[float, float] | None:
    """Fit ``|u_ref - u_N| = C sqrt(h_N^(2p) - h_ref^(2p))`` (least squares in log scale).

    If the true errors are ``C h^p`` and the spaces are nested, Galerkin orthogonality in the
    energy inner product gives ``|u_ref - u_N|^2 = |u - u_N|^2 - |u - u_ref|^2`` (exactly for the
    linear problem, approximately with contact), so this fit corrects the measured errors for
    the reference's own error. Returns (p, C), or None with fewer than two positive errors.
    """
    hs, errs = np.asarray(hs, float), np.asarray(errs, float)
    ok = errs > 0
    if ok.sum() < 2:
        return None
    hs, le = hs[ok], np.log(errs[ok])
    best = None
    for p in np.linspace(0.05, 3.0, 2951):
        g = 0.5 * np.log(hs ** (2 * p) - h_ref ** (2 * p))
        c = np.mean(le - g)
        r = float(np.sum((le - g - c) ** 2))
        if best is None or r < best[0]:
            best = (r, float(p), float(np.exp(c)))
    return best[1], best[2]


def triple_rates(errs: list[float], with_reference: bool = True) -> list[float | None]:
    """Triple-wise orders p_i = 1/2 log2((e_i^2 - e_{i+1}^2) / (e_{i+1}^2 - e_{i+2}^2)) of errors
    measured against a fine reference on meshes halved at each step.

    With nested spaces, Galerkin orthogonality gives |u_ref - u_N|^2 = |u - u_N|^2 - |u - u_ref|^2
    (exact without contact), so the differences of squared measured errors are those of the true
    errors and do not depend on the reference's own error: if |u - u_N| = C h^p, every p_i = p.
    ``with_reference`` appends the reference itself as the last level (its error against itself
    is 0), which is exact only if the reference mesh is the next halving of the last level.
    Entry i belongs to the triple that starts at level i; None where a difference is not positive.
    """
    e2 = [float(e) ** 2 for e in errs] + ([0.0] if with_reference else [])
    out: list[float | None] = []
    for a, b, c in zip(e2, e2[1:], e2[2:]):
        out.append(0.5 * math.log2((a - b) / (b - c)) if a > b > c else None)
    return out


def exact_solver(name: str | None = None) -> str:
    """The solver of the study: ``name`` if it is an installed exact solver, else the reference
    policy's first candidate (:func:`dualfem.experiments.reference.candidates`)."""

    allowed = [n for n, _ in candidates(only=(name,) if name else None)]
    if not allowed:
        known = ", ".join(n for n, _ in candidates()) or "(none installed)"
        raise InputError(f"--solver must be an installed exact solver ({known}), got {name!r}" if name else
                         "no exact reference solver is registered and installed")
    return allowed[0]


def study(deltas, Ns, ref_N, solver: str, scene: str = DEFAULT_SCENE, progress=print) -> dict:
    """Run the study with the exact ``solver`` (see :func:`exact_solver`); returns the JSON-able result dict.

    The reference solve must be trusted by :func:`dualfem.experiments.reference.trust` (solved,
    KKT residuals and certified error small); its certified relative energy-norm error is stored
    as ``reference.certified_error``.

    Memory-lean: one delta at a time, the reference QP is dropped after its delta, and the
    solvers' factorizations are freed (``store_of(qp).clear()``, :mod:`dualfem.numerics.linalg`) after
    every reference solve, so the peak is one fine QP plus one fine factorization (why:
    docs/measurements.md).
    """

    res = {"scene": scene, "solver": solver, "ref_N": ref_N, "Ns": list(Ns), "deltas": {},
           "params": {k: v for k, v in load_scene(scene, {"N": min(Ns)}).build().params.items()
                      if k not in ("N", "delta")}}
    t_start = time.perf_counter()
    for delta in deltas:
        t0 = time.perf_counter()
        qpf = load_scene(scene, {"N": ref_N, "delta": delta}).build()
        tb = time.perf_counter() - t0
        sf = run(solver, qpf)
        trusted, bound, _, why = trust(qpf, sf)
        store_of(qpf).clear()
        if not trusted:
            raise RuntimeError(f"reference solve at N={ref_N}, delta={delta:g} is not trusted: {why} "
                               f"({sf.status} {sf.message})")
        ref = {"N": ref_N, "ndof": qpf.n, "time_build_s": tb, "time_s": sf.time_s, "iterations": sf.iterations,
               "residuals": kkt_residuals(sf.residuals), "certified_error": bound,
               **level_quantities(qpf, sf)}
        progress(f"delta={delta:g} reference N={ref_N}: {qpf.n} unknowns, build {tb:.1f} s, "
                 f"setup {sf.time_s['setup']:.1f} s, solve {sf.time_s['solve']:.2f} s")
        xf = sf.x
        del sf
        levels = []
        for N in sorted(Ns):
            qpc = load_scene(scene, {"N": N, "delta": delta}).build()
            sc = run(solver, qpc)
            if not sc.ok:
                raise RuntimeError(f"solve failed at N={N}, delta={delta:g}: {sc.status} {sc.message}")
            lev = {"N": N, "h": 1.0 / N, "ndof": qpc.n, "time_s": sc.time_s,
                   **level_quantities(qpc, sc), **errors(qpf, xf, qpc, sc.x)}
            levels.append(lev)
            progress(f"delta={delta:g} N={N}: energy-norm error {lev['energy_norm']:.3e}, L2 {lev['L2']:.3e} "
                     f"({time.perf_counter() - t_start:.0f} s so far)")
        del qpf, xf
        gc.collect()  # the fine QP and factorization hold several GB at N = 1024: free them before the next delta
        for key in ("energy_norm", "K_norm", "L2"):
            for lev, r in zip(levels, rates([lv[key] for lv in levels])):
                lev[f"rate_{key}"] = r
        fits = {}
        for key in ("energy_norm", "K_norm", "L2"):
            f = fit_rate([lv["h"] for lv in levels], [lv[key] for lv in levels], 1.0 / ref_N)
            fits[key] = None if f is None else {"p": f[0], "C": f[1]}
        for key in ("energy", "contact_length", "total_force"):
            diffs = [abs(lv[key] - ref[key]) for lv in levels]
            for lev, dv, r in zip(levels, diffs, rates(diffs)):
                lev[f"diff_{key}"] = dv
                lev[f"rate_diff_{key}"] = r
        res["deltas"][f"{delta:g}"] = {"reference": ref, "levels": levels, "fits": fits,
                                       "time_s": time.perf_counter() - t0}
    return res

