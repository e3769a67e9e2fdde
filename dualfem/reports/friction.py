"""The friction report: render the validation study of :func:`dualfem.experiments.friction.study`.

Render only: :func:`render` writes ``friction.md`` and two figures (the 2D slip along the crack against the
closed form, the 3D slip over the disk with the stick nodes marked) from the study's numbers (what each case
measures: :mod:`dualfem.experiments.friction`). ``dualfem report friction`` runs the study, stores it as
``friction.json`` and calls :func:`render` (``--from-json`` re-renders without solving).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dualfem.core.errors import InputError
from dualfem.core.io import atomic_savefig, atomic_write_text
from dualfem.post.style import FIELD_CMAP, PALETTE

_KEYS = ("solver", "inclined", "penny", "stuck", "compare", "E", "nu", "delta", "stress_2d")


def check_study(res, src: str) -> None:
    """Refuse (InputError naming ``src``) a stored study :func:`render` cannot draw."""
    if not isinstance(res, dict) or any(k not in res for k in _KEYS):
        missing = [k for k in _KEYS if not isinstance(res, dict) or k not in res]
        raise InputError(f"{src} is not a friction.json written by 'dualfem report friction': missing {missing}")
    if not isinstance(res["inclined"], list) or not isinstance(res["penny"], list):
        raise InputError(f"{src}: 'inclined' and 'penny' must be lists of rows")


def _case(law: str, value: float) -> str:
    return "frictionless" if law == "none" else f"Tresca g = {value:g}" if law == "tresca" else \
        f"Coulomb mu_f = {value:g}"


def _fmt(v, spec=".2%") -> str:
    return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, spec)


def _outcome(r: dict) -> str:
    """The row's measured outcome: the slip error, or for a stick case whether the slip is zero to rounding."""
    if r["status"] != "solved":
        return f"{r['status']}"
    if "error" in r:
        return _fmt(r["error"])
    ratio = r.get("max_slip", 0.0) / max(r.get("scale", 1.0), 1e-300)
    return f"stick (max slip / max abs(x) = {ratio:.0e})"


def _inclined_table(rows: list[dict]) -> list[str]:
    levels = sorted({r["tip_size"] for r in rows}, reverse=True)
    cases = sorted({(r["angle"], r["law"], r["value"]) for r in rows})
    head = " | ".join(f"tip {t:g}: pairs, L2 error" for t in levels)
    out = [f"| angle | case | sigma_n | abs(tau) | tau_c | {head} |", "|---|---|---|---|---|" + "---|" * len(levels)]
    for angle, law, value in cases:
        rs = {r["tip_size"]: r for r in rows if (r["angle"], r["law"], r["value"]) == (angle, law, value)}
        first = next(iter(rs.values()))
        cells = " | ".join(f"{rs[t]['m']}, {_outcome(rs[t])}" if t in rs else "-" for t in levels)
        out.append(f"| {angle:g} | {_case(law, value)} | {first['sigma_n']:.3f} | {abs(first['tau']):.3f} | "
                   f"{first['tau_c']:.3f} | {cells} |")
    return out


def _pressure_table(rows: list[dict]) -> list[str]:
    """The nodal contact pressure lambda_j / w_j against sigma_n (relative L2, abs(x) <= 0.8 a), per angle and level:
    what Coulomb's threshold mu_f lambda_j is made of."""
    levels = sorted({r["tip_size"] for r in rows}, reverse=True)
    angles = sorted({r["angle"] for r in rows})
    out = ["| angle | sigma_n | " + " | ".join(f"tip {t:g}: frictionless / Coulomb" for t in levels) + " |",
           "|---|---|" + "---|" * len(levels)]
    for angle in angles:
        cells = []
        for t in levels:
            rs = [r for r in rows if r["angle"] == angle and r["tip_size"] == t and "pressure_error" in r]
            free = next((_fmt(r["pressure_error"]) for r in rs if r["law"] == "none"), "-")
            coul = ", ".join(_fmt(r["pressure_error"]) for r in rs if r["law"] == "coulomb") or "-"
            cells.append(f"{free} / {coul}")
        sn = next(r["sigma_n"] for r in rows if r["angle"] == angle)
        out.append(f"| {angle:g} | {sn:.3f} | " + " | ".join(cells) + " |")
    return out


def _penny_table(rows: list[dict]) -> list[str]:
    out = ["| mesh_size / tip_size | defect nodes | case | status | slip L2 error (r <= 0.8 a) | minus the "
           "frictionless error | max abs(slip across tau) / max abs(slip) | s |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        free = next((f for f in rows if f["law"] == "none" and f["mesh_size"] == r["mesh_size"]
                     and f["tip_size"] == r["tip_size"]), None)
        diff = r.get("error", np.nan) - free.get("error", np.nan) if free and r["law"] != "none" else None
        across = f"{r['max_across'] / r['max_slip']:.1e}" if "error" in r and r.get("max_slip") else "-"
        out.append(f"| {r['mesh_size']:g} / {r['tip_size']:g} | {r['m']} | {_case(r['law'], r['value'])} | "
                   f"{r['status']} | {_outcome(r) if r['status'] == 'solved' else '-'} | {_fmt(diff, '+.2%')} | "
                   f"{across} | {r['seconds']:.1f} |")
    return out


def _compare_table(rows: list[dict]) -> list[str]:
    out = ["| case | solver | status | setup s | solve s | iterations | certified error |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        its = ", ".join(f"{k}={v:g}" for k, v in r["iterations"].items()) or "-"
        status = r["status"] if r["status"] != "skipped" else f"skipped: {r['message'][:90]}"
        out.append(f"| {r['case']} | {r['solver']} | {status} | {_fmt(r['setup_s'], '.3f')} | "
                   f"{_fmt(r['solve_s'], '.3f')} | {its} | {_fmt(r['certified'], '.1e')} |")
    return out


def _headline(rows: list[dict]) -> list[str]:
    """Per case: the fastest solved solver (setup + solve) and how much longer Clarabel took, from the rows."""
    out = []
    for case in dict.fromkeys(r["case"] for r in rows):
        done = [r for r in rows if r["case"] == case and r["status"] == "solved" and r["solve_s"] is not None]
        if not done:
            continue
        t = {r["solver"]: (r["setup_s"] or 0.0) + r["solve_s"] for r in done}
        best = min(t, key=t.get)
        ref = f"; clarabel {t['clarabel'] / max(t[best], 1e-9):.0f} x that" if "clarabel" in t else ""
        out.append(f"* {case}: fastest certified answer {best} ({t[best]:.3f} s){ref}.")
    return out


def _figure_2d(rows: list[dict], outdir: Path) -> str | None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tip = min(r["tip_size"] for r in rows)
    pick = [r for r in rows if r["tip_size"] == tip and r["angle"] in (20.0, 30.0) and "slip" in r]
    if not pick:
        return None
    fig, ax = plt.subplots(figsize=(7, 4))
    for k, r in enumerate(sorted(pick, key=lambda r: (r["angle"], r["law"], r["value"]))):
        x, a = np.asarray(r["x"]), 0.05
        order = np.argsort(x)
        colour = PALETTE[k % len(PALETTE)]
        ax.plot(x[order] / a, np.asarray(r["exact"])[order], "-", color=colour, lw=1)
        ax.plot(x[order] / a, np.asarray(r["slip"])[order], "o", ms=3, color=colour,
                label=f"{r['angle']:g} deg, {_case(r['law'], r['value'])}" + (" (stick)" if "error" not in r else ""))
    ax.set_xlabel("x / a along the crack")
    ax.set_ylabel("slip |[u_t]|")
    ax.set_title("2D inclined closed crack: slip (markers) and closed form (lines)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    name = "friction_2d.png"
    atomic_savefig(fig, outdir / name, dpi=100)
    plt.close(fig)
    return name


def _figure_3d(rows: list[dict], outdir: Path) -> str | None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fine = [r for r in rows if "slip" in r and r["law"] != "none"]
    if not fine:
        return None
    h = min(r["tip_size"] for r in fine)
    fine = [r for r in fine if r["tip_size"] == h]
    fig, axes = plt.subplots(1, len(fine), figsize=(4.2 * len(fine), 4), squeeze=False)
    for ax, r in zip(axes[0], fine):
        px, py, s = np.asarray(r["px"]), np.asarray(r["py"]), np.abs(np.asarray(r["slip"]))
        stick = s <= 1e-8 * max(r["scale"], 1e-300)
        sc = ax.scatter(px[~stick], py[~stick], c=s[~stick], cmap=FIELD_CMAP, s=14)
        ax.scatter(px[stick], py[stick], marker="x", color="k", s=14, label="stick")
        ax.add_patch(plt.Circle((0, 0), 1.0, fill=False, lw=0.8))
        ax.set_aspect("equal")
        ax.set_title(_case(r["law"], r["value"]), fontsize=9)
        if (~stick).any():
            fig.colorbar(sc, ax=ax, shrink=0.8, label="slip along x")
        if stick.any():
            ax.legend(fontsize=7, loc="lower right")
    fig.suptitle("3D penny under compression and shear: slip over the disk")
    fig.tight_layout()
    name = "friction_3d.png"
    atomic_savefig(fig, outdir / name, dpi=100)
    plt.close(fig)
    return name


#: the friction study's other reports (each made by its own command, docs/reports.md): file, what it shows
COMPANIONS = (
    ("friction_curves.md", "work-precision of the dual methods, clarabel, cvxpy and osqp on a 2D crack and the "
                           "penny, Tresca and Coulomb, three tolerance tiers"),
    ("friction_fixed_point.md", "Coulomb by the fixed point: Tresca solves and the observed contraction against mu_f "
                                "per solver, pdas monolithic beside them; stick/slip maps along the crack and over "
                                "the disk"),
    ("friction_fractured.md", "a fractured body under compression plus shear with Coulomb friction: 400 cracks (2D) "
                              "and 100 disks (3D), every dual method, certified"),
    ("friction_cost.md", "pdas and mprgp: the cost of Tresca and Coulomb against the frictionless solve"),
    ("friction_uzawa.md", "uzawa, uzawa_auto, penalty: the cost of friction, Coulomb in the loop or by the fixed "
                          "point"),
)


def _companions(out: Path) -> list[str]:
    """Links to the companion reports that exist beside ``out/friction.md`` (none when rendered elsewhere)."""
    have = [(name, what) for name, what in COMPANIONS if (out / name).is_file()]
    if not have:
        return []
    return ["## The solver comparison at larger scale", "",
            *[f"- [{name}]({name}): {what}" for name, what in have], ""]


def render(res: dict, out: Path, command: str | None = None) -> Path:
    """Write ``out/friction.md`` and its figures; returns the Markdown path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    f2, f3 = _figure_2d(res["inclined"], out), _figure_3d(res["penny"], out)
    st = res["stuck"]
    lines = ["# Friction on the defects: validation against closed forms", "",
             f"Generated by `{command or 'dualfem report friction'}` (numbers: `friction.json` beside this page). "
             f"Solver of the validation cases: `{res['solver']}` (every answer certified by dualfem's judge; the "
             f"status column says so). E = {res['E']:g}, nu = {res['nu']:g}, delta = {res['delta']:g} (a free "
             "interface: only friction holds the faces). Cases and closed forms: `dualfem.experiments.friction`; "
             "keys and conventions: docs/friction.md." + (f" {res['note']}" if res.get("note") else ""), "",
             "## 2D: inclined closed crack (half-length a = 0.05 in the unit plate, gmsh)", "",
             f"Remote stress {res['stress_2d']}; on the crack plane sigma_n = -n.S.n, tau = t.S.n. Closed form "
             "(plane strain): slip 4 (1 - nu^2) (abs(tau) - tau_c) / E sqrt(a^2 - x^2), tau_c = g (Tresca) or "
             "mu_f sigma_n (Coulomb); stick when abs(tau) <= tau_c. Error: relative L2 over abs(x) <= 0.8 a with "
             "the nodal weights, per mesh level (tip_size: element size at the crack; pairs: friction nodes). "
             "The plate is 20 a wide: the closed form is for an infinite plate.", "",
             *_inclined_table(res["inclined"]), ""]
    if f2:
        lines += [f"![2D slip along the crack]({f2})", ""]
    lines += ["The nodal contact pressure lambda_j / w_j against sigma_n (relative L2 over abs(x) <= 0.8 a), the "
              "input of Coulomb's threshold mu_f lambda_j:", "", *_pressure_table(res["inclined"]), ""]
    lines += ["## 3D: penny crack (radius 1 in a cube of side 10) under compression and shear", "",
              f"sigma_zz = -{res.get('sigma_n_3d', 1.0):g}, sigma_xz = tau = {res.get('tau_3d', 0.5):g}. Closed "
              "form (Segedin's shear solution with the effective shear): slip along x 16 (1 - nu^2) (tau - tau_c) / "
              "(pi (2 - nu) E) sqrt(a^2 - r^2). The frictionless row is the same mesh's own discretization error: "
              "the target is a frictional error within a point of it.", "", *_penny_table(res["penny"]), ""]
    if f3:
        lines += [f"![3D slip over the disk]({f3})", ""]
    lines += ["## A stuck crack is the uncracked body", "",
              f"A horizontal crack under compression 1 and shear 0.3 with Tresca g = 10 (structured grid N = 16) "
              f"against the same grid without the crack: status {st['status']}, largest difference of the nodal "
              f"displacements {st['difference']:.1e} of the largest one, largest slip {st['max_slip']:.1e}; "
              f"{st['stick_nodes']} of {st['m']} nodes stick.", ""]
    if res["compare"]:
        lines += ["## Solvers on frictional scenes", "",
                  "Each solver on the 2D crack at 30 degrees (middle level) and on the penny (coarsest level); a "
                  "solver that does not take a law is skipped with its reason (`Solver.accepts`). Each solver gets a "
                  "fresh QP (no factorization shared between runs). Times are one "
                  "run each on a shared 2-core machine: read ratios, not seconds.", "",
                  *_compare_table(res["compare"]), "", *_headline(res["compare"]), "",
                  "The dual methods work on the defect's few unknowns (the exact reduction: dense Delassus or Newton "
                  "on the local space) and converge in a handful of Newton or outer steps; the interior point "
                  "factors the whole KKT system at each of its ~8 iterations, and for Coulomb repeats that per "
                  "fixed-point iteration (the counters above).", ""]
    lines += _companions(out)
    md = out / "friction.md"
    atomic_write_text(md, "\n".join(lines))
    return md
