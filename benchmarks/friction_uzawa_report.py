"""Render reports/friction_uzawa.md and its figure from benchmarks/results/friction_uzawa/friction_uzawa.json
(benchmarks/friction_uzawa.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def _f(v, fmt=".3f"):
    return "-" if v is None else format(v, fmt)


def _its(it: dict) -> str:
    return ", ".join(f"{k} {v}" for k, v in it.items())


def cost_table(rows: list[dict], scene: str) -> list[str]:
    base = {r["solver"]: r for r in rows if r["scene"] == scene and r["friction"] == "none"}
    out = [f"**{scene}** ({rows[0]['n'] if rows else '?'} unknowns in the first scene's QP; see the header)", "",
           "| solver | friction | status (claim) | setup s | solve s | solve / frictionless | (setup + solve) / "
           "frictionless | iterations | factorizations | space |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in (r for r in rows if r["scene"] == scene):
        b = base.get(r["solver"].split(" (")[0])
        ratio = r["solve_s"] / b["solve_s"] if b else None
        ratio2 = (r["setup_s"] + r["solve_s"]) / (b["setup_s"] + b["solve_s"]) if b else None
        out.append(f"| {r['solver']} | {r['friction']} | {r['status']} ({r['claim']}) | {_f(r['setup_s'])} | "
                   f"{_f(r['solve_s'])} | {_f(ratio, '.2f')} | {_f(ratio2, '.2f')} | {_its(r['iterations'])} | "
                   f"{r['factorizations']} | {r.get('space') or '-'} |")
    return out


def sweep_table(rows: list[dict], scene: str) -> list[str]:
    out = [f"**{scene}**", "", "| mu_f | solver | claim | solve s | iterations | largest observed contraction |",
           "|---|---|---|---|---|---|"]
    for r in (r for r in rows if r["scene"] == scene):
        out.append(f"| {r['mu_f']:g} | {r['solver']} | {r['claim']} | {_f(r['solve_s'])} | {_its(r['iterations'])} | "
                   f"{_f(r['coulomb_contraction'], '.3g')} |")
    return out


def findings(data: dict) -> list[str]:
    """Headline lines computed from the data (ratios of solve times; the fixed point's contraction per mu_f)."""
    out = []
    for sc in dict.fromkeys(r["scene"] for r in data["cost"]):
        rows = {(r["solver"], r["friction"]): r for r in data["cost"] if r["scene"] == sc}
        parts = []
        for name in ("uzawa", "uzawa_auto", "penalty"):
            b = rows.get((name, "none"))
            if b:
                parts.append(f"{name} Tresca {rows[(name, 'tresca')]['solve_s'] / b['solve_s']:.1f}x, Coulomb "
                             f"{rows[(name, 'coulomb')]['solve_s'] / b['solve_s']:.1f}x")
        over = [f"{name} {fr} {rows[(name, fr)]['solve_s'] / rows[(name, 'none')]['solve_s']:.1f}x"
                for name in ("uzawa", "uzawa_auto", "penalty") if (name, "none") in rows
                for fr, cap in (("tresca", 2.0), ("coulomb", 5.0))
                if rows[(name, fr)]["solve_s"] > cap * rows[(name, "none")]["solve_s"]]
        parts.append("beyond the issue's targets for pdas and mprgp (Tresca <= 2x, Coulomb <= 5x): "
                     + (", ".join(over) if over else "none"))
        inner, fixed = rows.get(("uzawa_auto", "coulomb")), rows.get(("uzawa_auto (coulomb=fixed_point)", "coulomb"))
        line = f"- {sc}: solve time against the frictionless solve: " + "; ".join(parts) + "."
        if inner and fixed:
            line += (f" Coulomb in the Uzawa loop is {fixed['solve_s'] / inner['solve_s']:.1f}x faster than the fixed "
                     f"point over Tresca solves ({inner['iterations'].get('outer')} outer iterations against "
                     f"{fixed['iterations'].get('outer')} in {fixed['iterations'].get('coulomb_iterations')} Tresca "
                     "solves: the threshold is updated with the pressure in every dual iteration, not after each "
                     "converged Tresca solve).")
        out.append(line)
        sw = [r for r in data["sweep"] if r["scene"] == sc and r["solver"].startswith("uzawa_auto (coulomb")
              and r["coulomb_contraction"]]
        slip = [r for r in sw if r["mu_f"] < 0.3]
        if slip:
            k = np.polyfit([r["mu_f"] for r in slip], [r["coulomb_contraction"] for r in slip], 1)
            out.append(f"  The fixed point's observed contraction grows linearly with mu_f while the crack slips "
                       f"(least squares: {k[0]:.2f} mu_f {k[1]:+.3f}); "
                       f"{max(r['iterations'].get('coulomb_iterations', 0) for r in sw)} Tresca solves at most.")
        onset = [r for r in data["sweep"] if r["scene"] == sc and r["mu_f"] == 0.3]
        if onset:
            claims = ", ".join(f"{r['solver']} {r['claim']}" for r in onset)
            out.append("  At the onset of slip (mu_f = tau / sigma_n = 0.3, a degenerate problem: the whole crack on "
                       f"the disc's boundary with zero slip): {claims}"
                       " (claims: a stagnating Tresca solve or a Newton loop at its cap is reported, never solved).")
    return out


def figure(slip: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dualfem.post.style import PALETTE

    x = np.asarray(slip["x"])
    order = np.argsort(x)
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for i, kind in enumerate(("none", "tresca", "coulomb")):
        d = slip[kind]
        ax.plot(x[order], np.asarray(d["exact"])[order], color=PALETTE[i], linestyle="-", linewidth=1)
        ax.plot(x[order], np.asarray(d["slip"])[order], color=PALETTE[i], linestyle="none",
                marker="osD"[i], markersize=4, label=f"{kind}: L2 error {100 * d['l2']:.1f} %")
    ax.set_xlabel("x along the crack (a = 0.05)")
    ax.set_ylabel("slip [u_t] (uzawa_auto); lines: closed form")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def render(data: dict, report: Path) -> None:
    report.mkdir(parents=True, exist_ok=True)
    figdir = report / "friction_uzawa"
    figdir.mkdir(exist_ok=True)
    figure(data["slip"], figdir / "slip_2d.png")
    m = data["machine"]
    scenes = list(dict.fromkeys(r["scene"] for r in data["cost"]))
    lines = ["# Friction in uzawa, uzawa_auto and penalty: cost, Coulomb in the loop or by the fixed point", "",
             "Generated by `python benchmarks/friction_uzawa.py --out benchmarks/results/friction_uzawa "
             "--report reports` "
             "(`--render-only` re-renders from `benchmarks/results/friction_uzawa/friction_uzawa.json`).", "",
             f"Machine: {m['cpu']}, {m['cores']} cores shared (load average {data['load_before']} before, "
             f"{data['load_after']} after), threads {m['threads']}, git {m['git']}, {data['date']}. "
             f"Times are medians of {data['repeats']} fresh solver instances (setup, solve); status: one run "
             "certified by the runner (`dualfem.experiments.runner.run`), claim in brackets. Scenes and loads: "
             "the docstring of benchmarks/friction_uzawa.py (Tresca g = 0.1, Coulomb mu_f = 0.2, shear 0.3 under "
             "compression 1: both slip). Setup: the solver's own work after the first instance (the QP keeps the "
             "factorization of K for the next ones).", "", "## Findings", ""] + findings(data) + [
             "", "## Cost of friction against the frictionless solve", ""]
    for sc in scenes:
        n = next(r["n"] for r in data["cost"] if r["scene"] == sc)
        mm = next(r["m"] for r in data["cost"] if r["scene"] == sc)
        lines += [f"{sc}: {n} unknowns, {mm} contact nodes.", ""] + cost_table(data["cost"], sc)[2:] + [""]
    lines += ["## Coulomb: fixed-point counts against mu_f (claims, not certified)", "",
              "`uzawa_auto (coulomb=fixed_point)` iterates Tresca solves (dualfem.numerics.coulomb); `uzawa_auto` "
              "takes the threshold from the current pressure inside the Uzawa loop; `penalty` uses the fixed point. "
              "mu_f >= 0.3 = tau / sigma_n sticks.", ""]
    for sc in scenes:
        lines += sweep_table(data["sweep"], sc) + [""]
    s = data["slip"]
    lines += ["## 2D slip against the closed form", "",
              "![slip](friction_uzawa/slip_2d.png)", "",
              "Relative L2 error of the slip over |x| <= 0.8 a (uzawa_auto, certified status): " +
              ", ".join(f"{k} {100 * s[k]['l2']:.1f} % ({s[k]['status']})" for k in ("none", "tresca", "coulomb")) +
              ". The mesh has few crack pairs (see the cost table): the error is the discretization's, the same "
              "for the three cases.", ""]
    (report / "friction_uzawa.md").write_text("\n".join(lines) + "\n")
