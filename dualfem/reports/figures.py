"""``dualfem report figures``: the paper's figures (reports/figures.md + reports/figures/*.png).

Every picture is drawn by :mod:`dualfem.figures` from a scene's QP and a registry solver's
Solution, so the same calls work in a notebook. The solutions of the pictures come from the
fastest exact solver available (:func:`dualfem.figures.pick_solver`: pdas, else uzawa, else
clarabel); the convergence histories come from the ``uzawa`` solver (the paper's method) and
from every other registered solver that records a per-iteration history.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from dualfem.cli.report import register_report
from dualfem.core.errors import InputError

#: deltas of the jump / pressure / history figures (the paper's range)
SWEEP = (1e-1, 1e-3, 1e-5, 1e-7, 1e-9)
#: the same in plain text (Markdown)
KEY_TEXT = {"dual_change": "max_j |l^{k+1}_j - l^k_j| in MPa"}
#: radius around the defect tips for the "stress at the tips" column (triangle centroids)
TIP_RADIUS = 0.05
#: history quantity per solver, first one found in the solver's history rows
HISTORY_KEYS = ("dual_change", "residual", "grad", "complementarity", "primal")
KEY_LABEL = {
    "dual_change": r"$\max_j |l^{k+1}_j - l^k_j|$ (MPa)",
    "residual": "relative |min(mu, c gap)|",
    "grad": "gradient norm of the solver's objective (for a penalty method it grows with the penalty parameter)",
    "complementarity": "complementarity residual",
    "primal": "primal residual",
}


def _save(fig, path: Path, dpi: int) -> str:
    from dualfem.core.io import atomic_savefig

    atomic_savefig(fig, path, dpi=dpi)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path.name


def history_key(sol) -> str | None:
    """The first key of :data:`HISTORY_KEYS` present in ``sol.history``."""
    from dualfem.post.figures import history_series

    for key in HISTORY_KEYS:
        if history_series(sol, key) is not None:
            return key
    return None


def solvers_with_history(exclude=(), probe_N: int = 8) -> list[str]:
    """Registered, installed solvers that record a per-iteration history (a key of
    :data:`HISTORY_KEYS`), found by one solve of a tiny f2 scene (N = ``probe_N``): libraries
    without a history are not run at full size just to find that out."""
    from dualfem.core.registry import solvers
    from dualfem.core.runner import run
    from dualfem.core.scene import load_scene

    qp = load_scene("f2", {"N": probe_N, "delta": 1e-5}).build()
    out = []
    for name, cls in sorted(solvers().items()):
        if name in exclude or cls.missing() is not None:
            continue
        if history_key(run(name, qp)) is not None:
            out.append(name)
    return out


class _Cases:
    """Solve each (scene, delta) once with a given solver and remember the result."""

    def __init__(self, N: int, progress):
        self.N = N
        self.progress = progress
        self._qp: dict = {}
        self._sol: dict = {}

    def qp(self, scene: str, delta: float):
        from dualfem.core.scene import load_scene

        key = (scene, delta)
        if key not in self._qp:
            self._qp[key] = load_scene(scene, {"N": self.N, "delta": delta}).build()
        return self._qp[key]

    def solve(self, solver: str, scene: str, delta: float, params: dict | None = None):
        from dualfem.core.runner import run

        key = (solver, scene, delta)
        if key not in self._sol:
            t0 = time.perf_counter()
            sol = run(solver, self.qp(scene, delta), params)
            self._sol[key] = sol
            self.progress(f"{scene} delta={delta:g} {solver}: {sol.status} {sol.iterations} "
                          f"({time.perf_counter() - t0:.1f} s)")
        return self._sol[key]


def generate(outdir: Path, N: int = 64, solver: str | None = None, scale: float = 300.0, dpi: int = 110,
             sweep=SWEEP, history_solvers: list[str] | None = None, progress=print) -> str:
    """Draw every figure into ``outdir/figures`` and return the Markdown text of figures.md."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dualfem.core import evaluator
    from dualfem.post import figures as F
    from dualfem.post.fields import Post
    from dualfem.core.registry import solvers

    exact = F.pick_solver(solver, exact=True)
    figdir = outdir / "figures"
    cases = _Cases(N, progress)
    rows = []          # table of the pictured solutions
    md = []

    def ok(sol, what):
        if sol.x is None:
            raise RuntimeError(f"{what}: solver {sol.solver} returned no solution ({sol.status}: {sol.message})")
        return sol

    def record(scene, delta, sol, name):
        qp = cases.qp(scene, delta)
        p = Post(qp, sol)
        tips = qp.maps["nodes"][:, qp.maps["defect_tips"]]
        cen = p.nodes[:, p.triangles].mean(axis=1)
        near = np.min(np.linalg.norm(cen[:, :, None] - tips[:, None, :], axis=0), axis=1) < TIP_RADIUS
        rows.append((scene, delta, name, sol, float(p.von_mises.max()), float(p.von_mises[near].max()) if near.any() else float("nan"),
                     float(p.defect["jump_normal"].max()),
                     int(evaluator.contact_set(qp, sol.x).sum()), qp.m, float(sol.multipliers.sum())))
        return p

    # ---------------------------------------------------------------- deformed bodies (Figs 2, 3, 4, 7)
    deformed = [("f1", 1e-5, "Fig. 2: f1 (pressing down), faces closed"),
                ("f2", 1e-7, "Fig. 3 (left): f2, delta = 1e-7, faces nearly glued"),
                ("f2", 1e-5, "Fig. 3 (right): f2, delta = 1e-5, a stress concentrator at the crack tip"),
                ("f2", 1e-1, "Fig. 4: f2, delta = 1e-1, a crack"),
                ("f3", 1e-1, "Fig. 7: f3 (pulling up), faces fully apart")]
    md.append("## Deformed body coloured by von Mises stress (paper Figs 2, 3, 4, 7)\n")
    md.append(f"Deformed configuration x + {scale:g} u(x); every triangle (P1: constant stress) coloured by its "
              "von Mises stress in MPa (plane strain: sigma_33 = lambda (eps_11 + eps_22) included); the defect "
              "faces are drawn in white. Each picture has its own colour scale (maximum in the table below).\n")
    for scene, delta, caption in deformed:
        sol = ok(cases.solve(exact, scene, delta), f"{scene} delta={delta:g}")
        p = record(scene, delta, sol, caption)
        fig, ax = plt.subplots(figsize=(6.2, 5.0))
        F.plot_deformed(cases.qp(scene, delta), p, ax=ax, scale=scale,
                        title=f"{scene}, delta = {delta:g}, N = {N}: x + {scale:g} u")
        fig.tight_layout()
        name = _save(fig, figdir / f"deformed_{scene}_delta{delta:g}.png", dpi)
        md.append(f"**{caption}.**\n\n![{scene} delta={delta:g}](figures/{name})\n")

    # ------------------------------------------------------------------ jump and faces (Figs 5, 6)
    f2 = [(f"delta = {d:g}", cases.qp("f2", d), ok(cases.solve(exact, "f2", d), f"f2 delta={d:g}")) for d in sweep]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    F.plot_jump(f2, ax=axes[0], unit=1e-5)
    axes[0].set_title("f2: normal jump [u_nu] along the defect", fontsize=10)
    F.plot_jump(f2, ax=axes[1], log=True)
    axes[1].set_title("the same on a log scale", fontsize=10)
    fig.tight_layout()
    name = _save(fig, figdir / "jump_f2.png", dpi)
    md.append("## Normal jump along the defect (paper Fig. 5)\n")
    md.append(f"f2, N = {N}, delta from 1e-1 to 1e-9. Left: [u_nu] in units of 1e-5 (the paper's scale); "
              "right: log scale, which shows that the open part keeps its extent while its opening shrinks "
              "with delta (the tips are not doubled, so the jump is 0 there).\n")
    md.append(f"![jump](figures/{name})\n")

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.0))
    for ax, d in zip(axes, (1e-1, 1e-5)):
        F.plot_faces(cases.qp("f2", d), cases.solve(exact, "f2", d), ax=ax, scale=scale,
                     title=f"f2, delta = {d:g}: faces X + {scale:g} u")
    fig.tight_layout()
    name = _save(fig, figdir / "faces_f2.png", dpi)
    md.append("## Shapes of the two faces (paper Fig. 6)\n")
    md.append(f"f2 at delta = 1e-1 and 1e-5: the upper face (red) and the lower face (blue), x + {scale:g} u, "
              "with the undeformed defect dashed.\n")
    md.append(f"![faces](figures/{name})\n")

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    F.plot_pressure(f2, ax=ax)
    ax.set_title(f"f2, N = {N}: contact pressure l = mu / w", fontsize=10)
    fig.tight_layout()
    name = _save(fig, figdir / "pressure_f2.png", dpi)
    md.append("## Contact pressure along the defect\n")
    md.append("The multipliers as a pressure, l_j = mu_j / w_j (MPa; the paper's dual variable "
              "l = -sigma_nu + [u_nu]/delta), f2 at the same deltas; zero where the faces are open.\n")
    md.append(f"![pressure](figures/{name})\n")

    # ---------------------------------------------------------------- convergence histories
    md.append("## Convergence histories\n")
    reg = solvers()
    hist_md = []
    if "uzawa" not in reg:
        md.append("**Not drawn: the `uzawa` solver is not registered in this installation**, so there is no Uzawa "
                  "history to show. `dualfem.figures.plot_history` draws it from `Solution.history` "
                  "(key `dual_change`) once the solver is available.\n")
    else:
        others = history_solvers if history_solvers is not None else solvers_with_history(exclude=("uzawa",))
        md.append(f"Left: the Uzawa method (solver `uzawa`, default parameters: r = "
                  f"{reg['uzawa'].defaults.get('r'):g}, tol_outer = {reg['uzawa'].defaults.get('tol_outer')}) — "
                  "the dual change max_j |l^{k+1}_j - l^k_j| (MPa) per outer iteration, for delta from 1e-1 to "
                  "1e-9. Right: the other registered solvers that record a per-iteration history, at delta = "
                  "1e-5 (solid) and 1e-9 (dashed), each with its own progress measure (named in the legend); "
                  "solvers without a history (direct/interior-point libraries) are listed below the plots. The "
                  "measures of different solvers are not comparable with each other (see the list below).\n")
        table = ["| scene | " + " | ".join(f"delta = {d:g}" for d in sweep) + " |",
                 "|---|" + "---|" * len(sweep)]
        agree = []
        no_hist: set[str] = set() if history_solvers is not None else \
            {n for n, c in reg.items() if c.missing() is None} - set(others) - {"uzawa"}
        measures: dict[str, str] = {}
        for scene in ("f1", "f2", "f3"):
            fig, axes = plt.subplots(1, 2, figsize=(12, 4.3))
            runs, cells = [], []
            for d in sweep:
                s = cases.solve("uzawa", scene, d)
                runs.append((f"delta = {d:g}", s))
                it = s.iterations
                cells.append(f"{it.get('outer', '?')} / {it.get('inner', '?')}" + ("" if s.ok else f" ({s.status})"))
                if s.x is not None:
                    ref = cases.solve(exact, scene, d)
                    if ref.x is not None and exact != "uzawa":
                        c = evaluator.compare(cases.qp(scene, d), s.x, s.multipliers, ref.x, ref.multipliers)
                        agree.append((scene, d, c["x_energy"], c["multipliers"], c["contact_mismatch"]))
            table.append(f"| {scene} | " + " | ".join(cells) + " |")
            F.plot_history(runs, ax=axes[0], key="dual_change", ylabel=KEY_LABEL["dual_change"],
                           title=f"{scene}: Uzawa, N = {N}", logx=True)
            colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
            other_runs = []
            for i, name_s in enumerate(others):
                for d, ls in ((1e-5, "-"), (1e-9, "--")):
                    s = cases.solve(name_s, scene, d)
                    key = history_key(s)
                    if key is None:
                        no_hist.add(name_s)
                        continue
                    measures[name_s] = key
                    other_runs.append((f"{name_s}, delta = {d:g}", s, {"color": colors[i % len(colors)], "ls": ls}))
            if other_runs:
                F.plot_history(other_runs, ax=axes[1], key=HISTORY_KEYS, ylabel="solver's own progress measure",
                               title=f"{scene}: other iterative solvers", logx=True)
            else:
                axes[1].text(0.5, 0.5, "no other solver records a history", ha="center", transform=axes[1].transAxes)
            axes[1].set_xlabel("iteration (as recorded by the solver)")
            fig.tight_layout()
            name = _save(fig, figdir / f"history_{scene}.png", dpi)
            hist_md.append(f"![history {scene}](figures/{name})\n")
        md.extend(hist_md)
        if measures:
            md.append("Progress measures drawn for the other solvers (the first of "
                      + ", ".join(f"`{k}`" for k in HISTORY_KEYS) + " found in each row of `Solution.history`):\n")
            for n_, k_ in sorted(measures.items()):
                md.append(f"- `{n_}`: `{k_}` ({KEY_TEXT.get(k_, KEY_LABEL[k_])})")
            md.append("")
        if no_hist - set(measures):
            no_hist -= set(measures)
            md.append("Solvers without a per-iteration history (not drawn): " + ", ".join(sorted(no_hist)) + ".\n")
        md.append(f"Uzawa iterations k_MU / m_MN (outer / total inner Newton) at N = {N} (compare with the "
                  "paper's Tables 1-3; the paper's mesh size is not stated):\n")
        md.extend(table)
        md.append("")
        if agree:
            md.append(f"Agreement of the Uzawa solutions with the exact solver `{exact}` "
                      "(`dualfem.evaluator.compare`: relative energy-norm difference of x, multiplier difference "
                      "relative to max(|mu_ref|, |F|), contact-set mismatches):\n")
            md.append("| scene | delta | x (energy norm) | multipliers | contact mismatch |")
            md.append("|---|---|---|---|---|")
            for scene, d, xe, mu, cm in agree:
                md.append(f"| {scene} | {d:g} | {xe:.1e} | {mu:.1e} | {cm} |")
            md.append("")

    # -------------------------------------------------------------------------------- summary table
    head = ["# Figures of the thin-defect problem (Zhiltsov & Maksimova 2023)\n",
            f"Generated by `dualfem report figures` with N = {N} (h = 1/{N}; {cases.qp('f2', 1e-5).n} unknowns, "
            f"{cases.qp('f2', 1e-5).m} doubled defect nodes), plane strain, E = 69000 MPa, nu = 0.3; displacements "
            f"magnified {scale:g} times. Solutions by the exact solver `{exact}` (evaluator KKT residuals "
            f"<= {max(evaluator.kkt_error(r[3].residuals) for r in rows):.1e} "
            "for the pictured cases). The paper does not state its delta for f1 and f3: we use 1e-5 for f1 "
            "(closed faces) and 1e-1 for f3 (so that the opening is visible). Every figure is drawn by a function "
            "of `dualfem.figures` from (qp, Solution); see that module's docstring for notebook use.\n",
            f"| picture | scene | delta | max von Mises (MPa) | max von Mises within {TIP_RADIUS:g} of a tip | "
            "max [u_nu] | closed nodes | total contact force |",
            "|---|---|---|---|---|---|---|---|---|"]
    for scene, delta, caption, sol, vm, vt, mj, nc, m, tf in rows:
        head.append(f"| {caption.split(':')[0]} | {scene} | {delta:g} | {vm:.3g} | {vt:.3g} | {mj:.3e} | {nc}/{m} | "
                    f"{tf:.4g} |")
    head.append("")
    return "\n".join(head + md) + "\n"


@register_report("figures", "the paper's figures: deformed bodies, jumps, faces, pressure, Uzawa histories")
def run(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="dualfem report figures", description=__doc__.splitlines()[0])
    ap.add_argument("--N", type=int, default=64, help="mesh size N (default 64)")
    ap.add_argument("--solver", default=None, help="exact solver for the pictures (default: pdas, else uzawa, else clarabel)")
    ap.add_argument("--scale", type=float, default=300.0, help="displacement magnification (default 300, as the paper)")
    ap.add_argument("--dpi", type=int, default=110)
    ap.add_argument("--history-solvers", default=None, metavar="A,B",
                    help="solvers besides uzawa whose histories are drawn (default: every registered one "
                         "that records a history, found by a solve of a tiny scene)")
    ap.add_argument("--out", default="reports", help="output directory (default reports/)")
    argv = list(argv)
    if argv[:1] == ["--"]:  # 'dualfem report KIND -- --opt ...' with older dispatchers
        argv = argv[1:]
    args = ap.parse_args(argv)
    from dualfem.core.errors import check_int, check_positive

    N = check_int("--N", args.N, 4, 1024)
    if N % 4:
        raise InputError(f"--N must be a multiple of 4 (the defect ends at x1 = 1/4, 3/4), got {N}")
    scale = check_positive("--scale", args.scale)
    dpi = check_int("--dpi", args.dpi, 30, 600)
    out = Path(args.out)
    hist = None
    if args.history_solvers is not None:
        from dualfem.core.registry import get_solver

        hist = [h.strip() for h in args.history_solvers.split(",") if h.strip()]
        for h in hist:
            get_solver(h)
    t0 = time.perf_counter()
    text = generate(out, N=N, solver=args.solver, scale=scale, dpi=dpi, history_solvers=hist,
                    progress=lambda m: print(m, file=sys.stderr, flush=True))
    from dualfem.core.io import atomic_write_text

    atomic_write_text(out / "figures.md", text + f"\n_Wall time {time.perf_counter() - t0:.0f} s._\n")
    print(f"wrote {out / 'figures.md'}", file=sys.stderr)
    return 0
