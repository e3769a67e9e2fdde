"""The plugins report: the second problem plugin (Signorini) and the template solver, measured.

Render only: :func:`render` draws and writes from the data of :func:`dualfem.experiments.plugins.collect`
(``dualfem report plugins``, :mod:`dualfem.cli.reports.plugins`, runs the study, then calls it).
Writes ``reports/plugins.md`` and ``reports/figures/plugins_signorini.png``:

* the Signorini scene (``problems/signorini.py``) solved by every registered, installed solver:
  status, iterations, time, difference to the exact reference, and the physical checks (total
  contact force = punch force; exact uniform pressure on a flat foundation);
* the figure: the deformed body on its obstacle, and the contact pressure along the bottom for
  several indentations, every exact solver overlaid;
* the cost of the template solver (``dual_gradient``, plain and accelerated) against the mesh
  size, next to the fastest exact solver: the honest numbers behind "slow".
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dualfem.core.io import atomic_savefig


def _solvers_section(data: dict) -> list[str]:
    p, N = data["scene"], data["N"]
    md = ["## Signorini contact: every solver\n",
          f"`problems/signorini.py`: elastic rectangle {p['width']:g} x {p['height']:g} (E = {p['E']:g}, nu = "
          f"{p['nu']:g}, plane {p['plane']}), N = {N} ({data['n']} unknowns, {data['m']} bottom nodes), pressed by a "
          f"flat frictionless punch (indentation {p['indent']:g}) onto a rigid obstacle with initial gap "
          f"g(x) = {p['obstacle']}. Reference: `{data['reference']}`. `x error` = relative energy-norm difference to "
          f"the reference; `punch + sum(mu)` = global vertical equilibrium (the punch force comes from rows of the "
          f"full stiffness matrix that the QP does not contain), relative to sum(mu).\n",
          "| solver | status | iterations | setup + solve (s) | KKT (evaluator) | x error | contact nodes | sum(mu) "
          "| punch + sum(mu) |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in data["solvers"]:
        if not r["ok"]:
            md.append(f"| {r['solver']} | {r['status']} | | | | | | | {r['message'][:60]} |")
            continue
        md.append(f"| {r['solver']} | {r['status']} | {r['iterations']} | {r['time_s']:.3f} | "
                  f"{r['kkt']:.1e} | {r['x_error']:.1e} | {r['contact']}/{r['m']} | "
                  f"{r['sum_mu']:.6g} | {r['equilibrium']:.1e} |")
    return md + [""]


def _flat_section(data: dict) -> list[str]:
    md = ["## Flat foundation: the exact answer\n",
          "With `obstacle = \"0\"` (`dualfem solve signorini_flat`) the exact solution is homogeneous uniaxial "
          "compression, which P1 elements reproduce: contact pressure p = E' indent / height on the whole bottom "
          "(E' = E / (1 - nu^2) in plane strain, E in plane stress).\n",
          "| N | plane | exact p | max relative error of mu / w (reference solver) | nodes in contact |",
          "|---|---|---|---|---|"]
    md += [f"| {r['N']} | {r['plane']} | {r['exact']:.6g} | {r['error']:.1e} | {r['contact']}/{r['m']} |"
           for r in data["flat"]]
    return md + [""]


def _draw_body(ax, fig_data: dict, N: int) -> None:
    """Left panel: the deformed mesh on the obstacle, the nodes in contact marked."""
    X, u = np.array(fig_data["nodes"]), np.array(fig_data["u"])
    height = fig_data["height"]
    scale = 0.1 * height / max(np.abs(u).max(), 1e-300)
    ax.triplot(X[0] + scale * u[0], X[1] + scale * u[1], np.array(fig_data["triangles"]), lw=0.3, color="0.4")
    xs, gap = np.array(fig_data["obstacle_x"]), np.array(fig_data["gap"])
    ax.fill_between(xs, -scale * gap, -scale * gap.max() - 0.05 * height, color="0.8", label="rigid obstacle")
    c = np.array(fig_data["contact_nodes"], dtype=int)
    ax.plot(X[0, c] + scale * u[0, c], X[1, c] + scale * u[1, c], "o", ms=3, color="C3", label="nodes in contact")
    ax.set_aspect("equal")
    ax.set_title(f"deformed body (displacements x {scale:.0f}), N = {N}")
    ax.legend(loc="upper right", fontsize=8)


def _draw_pressures(ax, fig_data: dict) -> None:
    """Right panel: contact pressure per indentation; reference as a line, other exact solvers as markers."""
    markers = "osd^v<>p*h"
    ref, exact = fig_data["reference"], fig_data["exact"]
    indents = sorted({r["indent"] for r in fig_data["pressures"]})
    for r in fig_data["pressures"]:
        k, j = indents.index(r["indent"]), exact.index(r["solver"])
        kw = dict(ls="-", lw=1.2, color=f"C{k}") if r["solver"] == ref else \
            dict(ls="none", marker=markers[j % len(markers)], ms=3.5, mfc="none", color=f"C{k}")
        ax.plot(r["x"], r["pressure"], label=f"indent {r['indent']:g}" if r["solver"] == ref else None, **kw)
    ax.set_xlabel("x1 along the bottom")
    ax.set_ylabel("contact pressure mu / w (MPa)")
    ax.set_title("contact pressure; line: " + ref + ", markers: " + ", ".join(n for n in exact if n != ref),
                 fontsize=8)
    ax.legend(fontsize=8)


def _figure_section(data: dict, out: Path, dpi: int) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    fig, axes = plt.subplots(1, 2, figsize=(12.5, 4.6))
    _draw_body(axes[0], data["figure"], data["N"])
    _draw_pressures(axes[1], data["figure"])
    fig.tight_layout()
    figdir = out / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    path = figdir / "plugins_signorini.png"
    atomic_savefig(fig, path, dpi=dpi)
    plt.close(fig)
    return [f"![Signorini contact](figures/{path.name})\n",
            "Left: the body on the obstacle (`dualfem solve signorini`). Right: contact pressure along the bottom for "
            "three punch indentations; every exact solver is drawn (markers on the reference line).\n"]


def _cost_section(data: dict) -> list[str]:
    fast = data["fast"]
    md = [f"## Cost of the template solver `{data['template']}`\n",
          f"Scene {data['scene_name']} (delta = 1e-5). Iterations of projected gradient on the dual (one sparse "
          "solve each) grow with the mesh, the accelerated variant (FISTA + restart, default) much less; "
          f"`{fast}` for scale. "
          "Times are wall-clock setup + solve on this machine (single runs); `max_n` is raised so that N = 128 "
          "(above the default skip threshold of 20000 unknowns) is measured too.\n",
          "| N | unknowns | plain: iterations | plain: time (s) | accelerated: iterations | accelerated: time (s) | "
          f"{fast}: time (s) | accelerated x error |",
          "|---|---|---|---|---|---|---|---|"]
    md += [f"| {r['N']} | {r['n']} | {r['plain_iterations']} ({r['plain_status']}) | {r['plain_time_s']:.3f} | "
           f"{r['accel_iterations']} ({r['accel_status']}) | {r['accel_time_s']:.3f} | "
           f"{r['fast_time_s']:.3f} ({r['fast_status']}) | {r['x_error']:.1e} |" for r in data["cost"]]
    return md + [""]


def render(data: dict, out: Path, dpi: int = 110) -> str:
    """The Markdown of plugins.md (and its figure in ``out/figures``) from
    :func:`dualfem.experiments.plugins.collect` data."""
    md = ["# Plugins: a second problem (Signorini contact) and the template solver\n",
          "Generated by `dualfem report plugins`. How to write such plugins: `docs/plugins.md`.\n"]
    md += _solvers_section(data) + _flat_section(data) + _figure_section(data, out, dpi) + _cost_section(data)
    return "\n".join(md)
