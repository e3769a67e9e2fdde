"""The figures report: the paper's figures and the scene library's (reports/figures.md + figures/*.png).

Render only: :func:`render` draws and writes from the results of :func:`dualfem.experiments.figures.collect`
(its frozen :class:`~dualfem.experiments.figures.Cases`: every Solution is looked up, none is
computed here); ``dualfem report figures`` (:mod:`dualfem.cli.reports.figures`) runs the study,
then calls it. Every picture is drawn by :mod:`dualfem.post.figures` from a scene's QP and a
registry solver's Solution, so the same calls work in a notebook. The pictured solutions come
from the reference policy's first exact solver unless ``--solver`` names one; the convergence
histories from the paper's method and from every other registered solver that records a
per-iteration history.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dualfem.core.io import atomic_savefig
from dualfem.experiments.figures import HISTORY_KEYS, OTHER_DELTAS, TIP_RADIUS, history_key
from dualfem.experiments.paper import PAPER_SOLVER
from dualfem.post import figures as F
from dualfem.post.fields import Post

#: the same in plain text (Markdown)
KEY_TEXT = {"dual_change": "max_j |l^{k+1}_j - l^k_j| in MPa"}
KEY_LABEL = {
    "dual_change": r"$\max_j |l^{k+1}_j - l^k_j|$ (MPa)",
    "residual": "relative |min(mu, c gap)|",
    "grad": "gradient norm of the solver's objective (for a penalty method it grows with the penalty parameter)",
    "complementarity": "complementarity residual",
    "primal": "primal residual",
}


def _save(fig, path: Path, dpi: int) -> str:

    atomic_savefig(fig, path, dpi=dpi)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path.name


def _deformed_section(data: dict, figdir: Path, scale: float, dpi: int) -> list[str]:
    """Paper Figs 2, 3, 4, 7: one picture per pictured solution."""
    import matplotlib.pyplot as plt


    cases, N = data["cases"], data["N"]
    md = ["## Deformed body coloured by von Mises stress (paper Figs 2, 3, 4, 7)\n",
          f"Deformed configuration x + {scale:g} u(x); every triangle (P1: constant stress) coloured by its "
          "von Mises stress in MPa (plane strain: sigma_33 = lambda (eps_11 + eps_22) included); the defect "
          "faces are drawn in white outlined in black. Colour map viridis (perceptually uniform, colour-blind safe; "
          "the stress is >= 0, so no diverging map). Each picture has its own colour scale (maximum in the table "
          "below).\n"]
    for r in data["rows"]:
        scene, delta = r["scene"], r["delta"]
        qp = cases.qp(scene, delta)
        fig, ax = plt.subplots(figsize=(6.2, 5.0))
        F.plot_deformed(qp, Post(qp, cases.solution(data["exact"], scene, delta)), ax=ax, scale=scale,
                        title=f"{scene}, delta = {delta:g}, N = {N}: x + {scale:g} u")
        fig.tight_layout()
        name = _save(fig, figdir / f"deformed_{scene}_delta{delta:g}.png", dpi)
        md.append(f"**{r['caption']}.**\n\n![{scene} delta={delta:g}](figures/{name})\n")
    return md


def _defect_sections(data: dict, figdir: Path, scale: float, dpi: int) -> list[str]:
    """Paper Figs 5 and 6 (jump, faces) and the contact pressure, the paper's scene over the delta sweep."""
    import matplotlib.pyplot as plt


    cases, N, exact, sc = data["cases"], data["N"], data["exact"], data["scene"]
    f2 = [(f"delta = {d:g}", cases.qp(sc, d), cases.solution(exact, sc, d)) for d in data["sweep"]]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    F.plot_jump(f2, ax=axes[0], unit=1e-5)
    axes[0].set_title("f2: normal jump [u_nu] along the defect", fontsize=10)
    F.plot_jump(f2, ax=axes[1], log=True)
    axes[1].set_title("the same on a log scale", fontsize=10)
    fig.tight_layout()
    md = ["## Normal jump along the defect (paper Fig. 5)\n",
          f"f2, N = {N}, delta from 1e-1 to 1e-9. Left: [u_nu] in units of 1e-5 (the paper's scale); "
          "right: log scale, which shows that the open part keeps its extent while its opening shrinks "
          "with delta (the tips are not doubled, so the jump is 0 there).\n",
          f"![jump](figures/{_save(fig, figdir / 'jump_f2.png', dpi)})\n"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.0))
    for ax, d in zip(axes, (1e-1, 1e-5), strict=True):
        F.plot_faces(cases.qp(sc, d), cases.solution(exact, sc, d), ax=ax, scale=scale,
                     title=f"f2, delta = {d:g}: faces X + {scale:g} u")
    fig.tight_layout()
    md += ["## Shapes of the two faces (paper Fig. 6)\n",
           f"f2 at delta = 1e-1 and 1e-5: the upper face (vermillion) and the lower face (blue), x + {scale:g} u, "
           "with the undeformed defect dashed.\n",
           f"![faces](figures/{_save(fig, figdir / 'faces_f2.png', dpi)})\n"]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    F.plot_pressure(f2, ax=ax)
    ax.set_title(f"f2, N = {N}: contact pressure l = mu / w", fontsize=10)
    fig.tight_layout()
    md += ["## Contact pressure along the defect\n",
           "The multipliers as a pressure, l_j = mu_j / w_j (MPa; the paper's dual variable "
           "l = -sigma_nu + [u_nu]/delta), f2 at the same deltas; zero where the faces are open.\n",
           f"![pressure](figures/{_save(fig, figdir / 'pressure_f2.png', dpi)})\n"]
    return md


def _scene_figure(item: dict, figdir: Path, scale: float, dpi: int) -> str:
    """scene_{name}.png: the deformed body with every defect (left), the jump along each defect (right)."""
    import matplotlib.pyplot as plt


    name, qp, r = item["name"], item["qp"], item["row"]
    post = Post(qp, item["sol"])
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.9), gridspec_kw={"width_ratios": [1.15, 1]})
    F.plot_deformed(qp, post, ax=axes[0], scale=scale, reference=True, contact=True, labels=True,
                    title=f"{name}: x + {scale:g} u, {qp.n} unknowns")
    F.plot_jump([("[u_nu]", qp, post)], ax=axes[1], unit=1e-5)
    if np.abs(post.defect["jump_normal"]).max() <= 1e-6 * np.abs(post.x).max():   # closed: do not zoom on rounding
        axes[1].set_ylim(-0.1, 1.0)
        axes[1].text(0.5, 0.5, "every defect closed along its whole length\n(|[u_nu]| at rounding level)",
                     ha="center", transform=axes[1].transAxes, fontsize=9)
    axes[1].set_title(f"{name}: normal jump along each defect (delta = "
                      + ", ".join(f"{d:g}" for d in r["deltas"]) + ")", fontsize=10)
    fig.tight_layout()
    return _save(fig, figdir / f"scene_{name}.png", dpi)


def _scenes_section(data: dict, figdir: Path, scale: float, dpi: int) -> list[str]:
    """The scene library (scenes/*.toml): one picture per scene and a table of its numbers."""
    items = data.get("scenes") or []
    if not items:
        return []
    md = ["## Scenes of the library: inclined, curved, kinked and several defects (gmsh meshes)\n",
          f"Every scene of `scenes/` (`dualfem list`; `dualfem solve NAME`), solved by `{data['exact']}` on its "
          "own gmsh mesh (`mesh_size`, refined to `tip_size` at the tips). Left: the deformed body "
          f"x + {scale:g} u coloured by the von Mises stress (MPa, own colour scale, viridis); both faces of every "
          "defect in white outlined in black, the undeformed defect dashed black, the closed nodes (the "
          "evaluator's contact set: normal jump <= 1e-6 max|x|) as vermillion dots on the deformed lower face, "
          "each defect's number (its place in "
          "`[[defects]]`, from 0) beside its first tip. Right: the normal jump [u_nu] along each defect "
          "(in units of 1e-5), s measured from its first tip; the normal is the tangent turned by +90 degrees.\n",
          f"| scene | what | unknowns | defects (delta) | closed nodes per defect | max von Mises (MPa) | "
          f"within {TIP_RADIUS:g} of a tip | max [u_nu] | KKT error | status |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for it in items:
        r = it["row"]
        closed = ", ".join(f"{c}/{n}" for c, n in zip(r["closed_per_defect"], r["nodes_per_defect"], strict=True))
        md.append(f"| {r['scene']} | {r['caption']} | {r['n']} | {r['defects']} ("
                  + ", ".join(f"{d:g}" for d in r["deltas"]) + f") | {closed} | {r['von_mises']:.3g} | "
                  f"{r['von_mises_tips']:.3g} | {r['max_jump']:.3e} | {r['kkt']:.1e} | {r['status']} |")
    md.append("")
    for it in items:
        name = _scene_figure(it, figdir, scale, dpi)
        md.append(f"**{it['name']}** ({it['row']['caption']})\n\n![{it['name']}](figures/{name})\n")
    return md


def _history_figure(data: dict, scene: str, figdir: Path, dpi: int) -> str:
    """history_{scene}.png: Uzawa's dual change (left), the other solvers' own measures (right)."""
    import matplotlib.pyplot as plt


    cases, uz = data["cases"], data["method"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.3))
    runs = [(f"delta = {d:g}", cases.solution(uz["solver"], scene, d)) for d in data["sweep"]]
    F.plot_history(runs, ax=axes[0], key="dual_change", ylabel=KEY_LABEL["dual_change"],
                   title=f"{scene}: Uzawa, N = {data['N']}", logx=True)
    colors = F.LINE_COLORS
    other = []
    for i, name in enumerate(uz["others"]):
        for d, ls in OTHER_DELTAS:
            s = cases.solution(name, scene, d)
            if history_key(s) is not None:
                other.append((f"{name}, delta = {d:g}", s, {"color": colors[i % len(colors)], "ls": ls}))
    if other:
        F.plot_history(other, ax=axes[1], key=HISTORY_KEYS, ylabel="solver's own progress measure",
                       title=f"{scene}: other iterative solvers", logx=True)
    else:
        axes[1].text(0.5, 0.5, "no other solver records a history", ha="center", transform=axes[1].transAxes)
    axes[1].set_xlabel("iteration (as recorded by the solver)")
    fig.tight_layout()
    return _save(fig, figdir / f"history_{scene}.png", dpi)


def _history_tables(data: dict) -> list[str]:
    """Progress measures, solvers without history, Uzawa's counts and its agreement with the exact solver."""
    uz, sweep, md = data["method"], data["sweep"], []
    if uz["measures"]:
        md.append("Progress measures drawn for the other solvers (the first of "
                  + ", ".join(f"`{k}`" for k in HISTORY_KEYS) + " found in each row of `Solution.history`):\n")
        md += [f"- `{n_}`: `{k_}` ({KEY_TEXT.get(k_, KEY_LABEL[k_])})" for n_, k_ in sorted(uz["measures"].items())]
        md.append("")
    if uz["no_history"]:
        md.append("Solvers without a per-iteration history (not drawn): " + ", ".join(uz["no_history"]) + ".\n")
    md += [f"Uzawa iterations k_MU / m_MN (outer / total inner Newton) at N = {data['N']} (compare with the "
           "paper's Tables 1-3; the paper's mesh size is not stated):\n",
           "| scene | " + " | ".join(f"delta = {d:g}" for d in sweep) + " |", "|---|" + "---|" * len(sweep)]
    for scene in data["loads"]:
        cells = [uz["counts"][(scene, d)] for d in sweep]
        md.append(f"| {scene} | " + " | ".join(f"{c['outer']} / {c['inner']}" + ("" if c["ok"] else f" ({c['status']})")
                                               for c in cells) + " |")
    md.append("")
    if uz["agree"]:
        md += [f"Agreement of the Uzawa solutions with the exact solver `{data['exact']}` "
               "(`dualfem.evaluator.compare`: relative energy-norm difference of x, multiplier difference "
               "relative to max(|mu_ref|, |F|), contact-set mismatches):\n",
               "| scene | delta | x (energy norm) | multipliers | contact mismatch |", "|---|---|---|---|---|"]
        md += [f"| {a['scene']} | {a['delta']:g} | {a['x_energy']:.1e} | {a['multipliers']:.1e} | "
               f"{a['contact_mismatch']} |" for a in uz["agree"]]
        md.append("")
    return md


def _history_section(data: dict, figdir: Path, dpi: int) -> list[str]:
    md = ["## Convergence histories\n"]
    uz = data["method"]
    if uz is None:
        return md + [f"**Not drawn: the `{PAPER_SOLVER}` solver is not registered in this installation**, so "
                     "there is no Uzawa history to show. `dualfem.post.figures.plot_history` draws it from "
                     "`Solution.history` (key `dual_change`) once the solver is available.\n"]
    md.append(f"Left: the Uzawa method (solver `{uz['solver']}`, default parameters: r = "
              f"{uz['defaults'].get('r'):g}, tol = {uz['defaults'].get('tol', uz['defaults'].get('tol_outer'))}"
              f"{', tol_mode = ' + str(uz['defaults']['tol_mode']) if 'tol_mode' in uz['defaults'] else ''}) — "
              "the dual change max_j |l^{k+1}_j - l^k_j| (MPa) per outer iteration, for delta from 1e-1 to "
              "1e-9. Right: the other registered solvers that record a per-iteration history, at delta = "
              "1e-5 (solid) and 1e-9 (dashed), each with its own progress measure (named in the legend); "
              "solvers without a history (direct/interior-point libraries) are listed below the plots. The "
              "measures of different solvers are not comparable with each other (see the list below).\n")
    md += [f"![history {scene}](figures/{_history_figure(data, scene, figdir, dpi)})\n" for scene in data["loads"]]
    return md + _history_tables(data)


def _head(data: dict, scale: float) -> list[str]:
    qp, N = data["cases"].qp(data["scene"], 1e-5), data["N"]
    head = ["# Figures of the thin-defect problem (Zhiltsov & Maksimova 2023)\n",
            f"Generated by `dualfem report figures` with N = {N} (h = 1/{N}; {qp.n} unknowns, "
            f"{qp.m} doubled defect nodes), plane strain, E = 69000 MPa, nu = 0.3; displacements "
            f"magnified {scale:g} times. Solutions by the exact solver `{data['exact']}` (evaluator KKT residuals "
            f"<= {max(r['kkt'] for r in data['rows']):.1e} "
            "for the pictured cases). The paper does not state its delta for f1 and f3: we use 1e-5 for f1 "
            "(closed faces) and 1e-1 for f3 (so that the opening is visible). Every figure is drawn by a function "
            "of `dualfem.post.figures` from (qp, Solution); see that module's docstring for notebook use.\n",
            f"| picture | scene | delta | max von Mises (MPa) | max von Mises within {TIP_RADIUS:g} of a tip | "
            "max [u_nu] | closed nodes | total contact force |",
            "|---|---|---|---|---|---|---|---|---|"]
    head += [f"| {r['caption'].split(':')[0]} | {r['scene']} | {r['delta']:g} | {r['von_mises']:.3g} | "
             f"{r['von_mises_tips']:.3g} | {r['max_jump']:.3e} | {r['closed']}/{r['m']} | {r['total_force']:.4g} |"
             for r in data["rows"]]
    return head + [""]


def render(data: dict, outdir: Path, scale: float = 300.0, dpi: int = 110) -> str:
    """Draw every figure into ``outdir/figures`` from :func:`dualfem.experiments.figures.collect`
    data and return the Markdown text of figures.md (no solver runs: every Solution is in ``data``)."""
    import matplotlib

    matplotlib.use("Agg")
    figdir = outdir / "figures"
    md = _deformed_section(data, figdir, scale, dpi) + _defect_sections(data, figdir, scale, dpi)
    md += _scenes_section(data, figdir, scale, dpi)
    md += _history_section(data, figdir, dpi)
    return "\n".join(_head(data, scale) + md) + "\n"
