"""The stability report: reports/stability.md from a ``dualfem stress`` run (render only).

``dualfem report stability RESULTS [OUTPUT.md]`` (:mod:`dualfem.cli.reports.stability`) reads the
results (:func:`dualfem.experiments.stress.load_results`) and calls :func:`render`.

Colour maps (outcome, error, iterations, time) per axis of the grid, the boundaries where each
solver stops being correct (with the solver's own message), the list of silent wrong answers
(ours and third-party, with their scenes), qpbenchmark's correct rate of ``solved`` claims per
solver and axis, and Uzawa's r x delta map beside its default setting.
Figures go to ``reports/stability/`` next to the Markdown file; every file is written atomically.
"""
from __future__ import annotations

import copy
import math
from collections import Counter, defaultdict
from pathlib import Path

from dualfem.core.io import atomic_savefig
from dualfem.experiments.stress_grid import BASE
from dualfem.reports._stability_correct import correct_rate_section
from dualfem.reports._stability_findings import _findings

COLORS = {"correct": "#2e9d4f", "failed": "#f0a030", "flagged": "#f5d040", "timeout": "#c77c2a",
          "crashed": "#8c4a1a", "silent_wrong": "#d62728", "unverified": "#9ecae1", "skipped": "#d9d9d9"}
SYMBOL = {"correct": "ok", "failed": "F", "flagged": "FL", "timeout": "T", "crashed": "X",
          "silent_wrong": "WRONG", "unverified": "?", "skipped": "-"}
AXIS_TITLE = {
    "delta": "fracture parameter delta (default solver parameters)",
    "r": "Uzawa augmentation parameter r x delta",
    "units": "units (same physics, entries scaled by up to 1e6)",
    "load": "load magnitude (x the base scene's load)",
    "nu": "Poisson ratio nu (plane strain)",
    "N": "mesh size N (unknowns ~ 2 N^2)",
}


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _sortkey(v):
    return (0, v) if isinstance(v, (int, float)) else (1, str(v))


def _grid(recs, rowf, colf):
    rows = sorted({rowf(r) for r in recs}, key=_sortkey)
    cols = sorted({colf(r) for r in recs}, key=_sortkey)
    cell = {(rowf(r), colf(r)): r for r in recs}
    return rows, cols, cell


def _heatmaps(recs, rowf, colf, title, rowlabel, collabel, path: Path, keep_col_order=None) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib import patheffects
    from matplotlib.colors import ListedColormap

    rows, cols, cell = _grid(recs, rowf, colf)
    if keep_col_order:
        cols = [c for c in keep_col_order if c in cols]
    nr, nc = len(rows), len(cols)
    fig, axs = plt.subplots(1, 4, figsize=(4.2 * 4, 0.45 * nr + 2.2), constrained_layout=True)
    outs = list(COLORS)
    cmap = ListedColormap([COLORS[o] for o in outs])
    A = np.full((nr, nc), np.nan)
    E = np.full((nr, nc), np.nan)
    IT = np.full((nr, nc), np.nan)
    TM = np.full((nr, nc), np.nan)
    for i, rv in enumerate(rows):
        for j, cv in enumerate(cols):
            r = cell.get((rv, cv))
            if r is None:
                continue
            A[i, j] = outs.index(r["grade"])
            if r.get("err_x_energy") is not None and r["err_x_energy"] > 0:
                E[i, j] = math.log10(max(r["err_x_energy"], 1e-17))
            if r.get("main_iterations"):
                IT[i, j] = math.log10(r["main_iterations"])
            t = (r.get("setup_s") or 0) + (r.get("solve_s") or 0)
            if t > 0 and r["grade"] not in ("skipped", "timeout", "crashed"):
                TM[i, j] = math.log10(t)
    panels = [(A, "outcome", cmap, (-0.5, len(outs) - 0.5)),
              (np.clip(E, -14, 1), "log10 rel. energy-norm error (clipped to [-14, 1])", "viridis", (-14, 1)),
              (IT, "log10 iterations (main counter)", "magma_r", None),
              (TM, "log10 time setup+solve [s]", "cividis", None)]
    for ax, (M, name, cm, lim) in zip(axs, panels):
        kw = {"vmin": lim[0], "vmax": lim[1]} if lim else {}
        im = ax.imshow(np.ma.masked_invalid(M), cmap=cm, aspect="auto", **kw)
        ax.set_xticks(range(nc), [_fmt(c) for c in cols], rotation=45, ha="right", fontsize=8)
        ax.set_yticks(range(nr), [_fmt(r) for r in rows], fontsize=8)
        ax.set_xlabel(collabel, fontsize=8)
        ax.set_title(name, fontsize=9)
        for i in range(nr):
            for j in range(nc):
                if np.isnan(M[i, j]):
                    continue
                txt = SYMBOL[outs[int(M[i, j])]] if name == "outcome" else f"{M[i, j]:.1f}"
                ax.text(j, i, txt, ha="center", va="center", fontsize=6.5, color="black",
                        path_effects=[patheffects.withStroke(linewidth=1.5, foreground="white")])
        if not name.startswith("outcome"):
            fig.colorbar(im, ax=ax, shrink=0.8)
    axs[0].set_ylabel(rowlabel, fontsize=8)
    fig.suptitle(title, fontsize=10)

    atomic_savefig(fig, path, dpi=110)
    plt.close(fig)
    return path


def _table(recs, rowf, colf, keep_col_order=None) -> str:
    rows, cols, cell = _grid(recs, rowf, colf)
    if keep_col_order:
        cols = [c for c in keep_col_order if c in cols]
    out = ["| | " + " | ".join(_fmt(c) for c in cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for rv in rows:
        cells = []
        for cv in cols:
            r = cell.get((rv, cv))
            if r is None:
                cells.append("")
                continue
            s = SYMBOL[r["grade"]]
            if r.get("err_x_energy") is not None:
                s += f" {r['err_x_energy']:.0e}"
            if r.get("main_iterations"):
                s += f" ({int(r['main_iterations'])})"
            cells.append(s)
        out.append(f"| {_fmt(rv)} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def _scene_str(r: dict) -> str:
    s = dict(r["scene"])
    keep = {k: v for k, v in s.items() if k in ("load", "N", "delta", "E", "nu", "plane", "load_scale", "width")}
    txt = ", ".join(f"{k}={_fmt(v)}" for k, v in keep.items())
    if r.get("solver_params"):
        txt += "; " + ", ".join(f"{k}={_fmt(v)}" for k, v in r["solver_params"].items())
    return txt


def _boundaries(recs, colf, colname) -> list[str]:
    """Per solver: where it is correct, and the first values where it is not (with its message)."""
    lines = []
    by = defaultdict(list)
    for r in recs:
        sp_ = r.get("solver_params")
        by[r["solver"] + (" " + ",".join(f"{k}={_fmt(v)}" for k, v in sp_.items()) if sp_ else "")].append(r)
    for s, rs in sorted(by.items()):
        rs = sorted(rs, key=lambda r: _sortkey(colf(r)))
        good = [colf(r) for r in rs if r["grade"] == "correct"]
        bad = [r for r in rs if r["grade"] not in ("correct", "skipped")]
        skipped = [r for r in rs if r["grade"] == "skipped"]
        if not bad and not skipped:
            lines.append(f"- **{s}**: correct at every {colname} tried ({', '.join(_fmt(c) for c in good)}).")
            continue
        parts = []
        if good:
            parts.append(f"correct at {colname} = {', '.join(_fmt(c) for c in good)}")
        for r in bad:
            why = (r.get("message") or "").strip() or (r.get("reason") or "")
            e = f", error {r['err_x_energy']:.1e}" if r.get("err_x_energy") is not None else ""
            k = f", KKT {r['kkt_error']:.1e}" if r.get("kkt_error") is not None else ""
            parts.append(f"{colname} = {_fmt(colf(r))}: **{r['grade']}** (status {r.get('status')}{e}{k}"
                         f"{'; ' + why[:160] if why else ''})")
        if skipped:
            parts.append(f"skipped at {colname} = {', '.join(_fmt(colf(r)) for r in skipped)} "
                         f"({(skipped[0].get('message') or '')[:140]})")
        lines.append(f"- **{s}**: " + "; ".join(parts) + ".")
    return lines


def _by_product(recs) -> dict:
    out = defaultdict(list)
    for r in recs:
        if r["grade"] == "correct" and r.get("main_iterations"):
            out[float(f"{r['coords']['r'] * r['coords']['delta']:.3g}")].append(r["main_iterations"])
    return out


def _scatter_r_delta(recs, solver: str, path: Path) -> None:
    """Outer iterations against the dimensionless r x delta, one colour per outcome."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0), constrained_layout=True)
    for o in COLORS:
        pts = [(r["coords"]["r"] * r["coords"]["delta"], r["main_iterations"]) for r in recs
               if r["grade"] == o and r.get("main_iterations")]
        if pts:
            x, y = zip(*pts)
            ax.scatter(x, y, s=28, color=COLORS[o], edgecolor="k", linewidth=0.4, label=o)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("r x delta  (augmentation / interface stiffness 1/delta)")
    ax.set_ylabel("outer iterations")
    ax.set_title(f"{solver}: outer iterations against r x delta (all r, all delta)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)

    atomic_savefig(fig, path, dpi=110)
    plt.close(fig)


def _classification(meta: dict) -> list[str]:
    """How runs are graded: the one policy of :mod:`dualfem.verify.grading`, in words."""
    refs = meta.get("references") or []
    return ["## How a run is graded", "",
            "Every run is compared with a reference solution of the same QP, chosen by dualfem's one reference "
            "policy (`dualfem.experiments.reference`): the first trusted run of "
            f"{', '.join(f'`{r}`' for r in refs) or '?'} "
            "(a run of a reference solver is compared with the next one, never with itself). A reference is trusted "
            f"only if it claims solved, its own independent KKT residual is below {meta.get('ref_kkt', 1e-7):g} and "
            "its certified energy-norm error bound (from the QP alone) is finite. On the *units* and *load* axes the "
            "reference "
            "is the base scene's reference mapped by exact physics (change of units; x(sF) = s x(F)), so no solver is "
            "trusted on scaled data.", "",
            "The error is the relative energy-norm error |x - x_ref|_K / |x_ref|_K. With t the tolerance the solver "
            "instance declares and b the reference's certified error bound (`dualfem.verify.grading.grade`, the same "
            "policy "
            "as `dualfem compare` and `dualfem bench`):", "",
            "- **correct** (`ok`): status solved, KKT residuals <= t and error <= t + b;",
            "- **failed** (`F`, honest): the status says not solved (max_iter, stagnation, numerical_error, ...);",
            "- **flagged** (`FL`, honest): status solved, but the evaluator's largest KKT residual is > t, so a user "
            "checking residuals sees it;",
            "- **timeout** (`T`) / **crashed** (`X`): the harness killed the run or the process died (honest: no "
            "answer);",
            "- **silent wrong answer** (`WRONG`): status solved, KKT residuals <= t, error > t + b;",
            "- **unverified** (`?`): no trusted reference;",
            "- **skipped** (`-`): the solver does not apply, or the previous N already exceeded the time or memory "
            "budget.",
            "",
            "Declared tolerances: " + ", ".join(f"`{k}` {v:g}" for k, v in sorted(meta.get("tolerances", {}).items()))
            + ". Solvers wrapping a third-party library (non-empty `requires`): "
            + ", ".join(f"`{k}`" for k, v in sorted(meta.get("third_party", {}).items()) if v) + ".", "",
            "Cells of the tables: grade symbol, error, (main iteration counter: `outer` for Uzawa, else the "
            "solver's only counter).", ""]


def _head(meta: dict, recs: list) -> list[str]:
    L = ["# Numerical stability under stress", "",
         "Generated by `dualfem report stability RESULTS` from the runs of `dualfem stress` "
         f"({'QUICK grid' if meta.get('quick') else 'full grid'}"
         f"{'' if meta.get('complete', True) else ', INCOMPLETE: not every run finished'}; "
         f"started {meta.get('started', '?')}, finished {meta.get('finished', '?')}; "
         f"{len(recs)} runs; code at commit {meta.get('git_commit') or '?'}"
         + "".join(f"; resumed {r.get('started')} at commit {r.get('git_commit')} for "
                   f"{', '.join(r.get('solvers') or [])} on axis {', '.join(r.get('axes') or [])}"
                   for r in meta.get("resumed", []))
         + "). Do not edit by hand: rerun "
         "`dualfem stress` and `dualfem report stability benchmarks/results/stress`.", ""]
    env = meta.get("environment", {})
    if env:
        L += [f"Machine: {env.get('cpus')} CPUs, Python {env.get('python')}, "
              + ", ".join(f"{k} {v}" for k, v in env.get("versions", {}).items()) + ".", ""]
    return L + _classification(meta)


def _summary(recs: list) -> list[str]:
    """Counts per solver and grade, then every silent wrong answer and the unverified runs."""
    solvers = sorted({r["solver"] for r in recs})
    c = {s: Counter(r["grade"] for r in recs if r["solver"] == s) for s in solvers}
    outs = [o for o in COLORS if any(c[s][o] for s in solvers)]
    L = ["## Summary", "", "| solver | " + " | ".join(outs) + " |", "|---" * (len(outs) + 1) + "|"]
    L += [f"| {s} | " + " | ".join(str(c[s][o]) for o in outs) + " |" for s in solvers]
    L.append("")
    wrong = [r for r in recs if r["grade"] == "silent_wrong"]
    ours = [r for r in wrong if not r.get("third_party")]
    theirs = [r for r in wrong if r.get("third_party")]
    L += ["## Silent wrong answers", "",
          f"**Our solvers: {len(ours)}** (target 0). **Third-party solvers: {len(theirs)}.**", ""]
    if wrong:
        L += _unbounded_note(wrong)
        L += ["| solver | axis | scene; solver params | status | error | KKT | reference (certified bound) | message |",
              "|---|---|---|---|---|---|---|---|"]
        for r in sorted(wrong, key=lambda r: (bool(r.get("third_party")), r["solver"], r["axis"])):
            b = r.get("ref_bound")
            ref = f"{r.get('ref_solver')} ({'not recorded' if b is None else format(b, '.1e')})"
            L.append(f"| {r['solver']}{'' if r.get('third_party') else ' (ours)'} | {r['axis']} | {_scene_str(r)} | "
                     f"{r.get('status')} | {r['err_x_energy']:.1e} | {r['kkt_error']:.1e} | {ref} | "
                     f"{(r.get('message') or '')[:80]} |")
        L.append("")
    L += _findings(recs)
    unv = [r for r in recs if r["grade"] == "unverified"]
    if unv:
        L += [f"Unverified runs ({len(unv)}): " + "; ".join(
            f"{r['solver']} {r['axis']} {_scene_str(r)} ({(r.get('reason') or '')[:120]})" for r in unv[:20]), ""]
    return L


def _unbounded_note(wrong: list) -> list[str]:
    """A caveat when silent wrong answers were graded without the reference's certified bound."""
    nob = [r for r in wrong if r.get("ref_bound") is None]
    if not nob:
        return []
    errs = sorted(r["err_x_energy"] for r in nob)
    tols = sorted({r.get("tol") if r.get("tol") is not None else r.get("tolerance") for r in nob}, key=str)
    return [f"**Caveat: {len(nob)} of these {len(wrong)} were graded without the reference's certified error "
            "bound** (the records predate it, so the grade's slack b is 0): their errors "
            f"({errs[0]:.1e} to {errs[-1]:.1e}) are measured against references "
            f"({', '.join(sorted({str(r.get('ref_solver')) for r in nob}))}) whose own error is not known "
            f"to be below the declared tolerance ({', '.join(str(t) for t in tols)}). They are wrong answers "
            "only if the reference is more accurate than that; rerunning `dualfem stress` records the bound "
            "and settles it.", ""]


def _section(fig_dir: Path, rs: list, axis: str, rowf, colf, rowlabel: str, collabel: str, colname: str,
             extra=None, suffix: str = "", col_order=None) -> list[str]:
    """One axis of the grid: colour maps, the table, the boundaries."""
    if not rs:
        return []
    name = f"{axis}{suffix}"
    _heatmaps(rs, rowf, colf, AXIS_TITLE.get(axis, axis) + (f" [{suffix.strip('_')}]" if suffix else ""),
              rowlabel, collabel, fig_dir / f"{name}.png", col_order)
    L = [f"### {AXIS_TITLE.get(axis, axis)}{(' - ' + suffix.strip('_')) if suffix else ''}", "",
         f"![{name}]({fig_dir.name}/{name}.png)", "", _table(rs, rowf, colf, col_order), ""]
    return L + (extra or []) + ["Boundaries:", ""] + _boundaries(rs, colf, colname) + [""]


def _solver_row(r) -> str:
    p = r.get("solver_params") or {}
    return r["solver"] + ("" if not p else " " + ",".join(f"{k}={_fmt(v)}" for k, v in p.items()))


def _with_coords(rec, **coords):
    """A copy of the run record ``rec`` (a Row or a dict) with some coordinates replaced."""
    c = copy.copy(rec)
    if hasattr(c, "extra"):
        c.extra = dict(c.extra)
    c["coords"] = {**rec["coords"], **coords}
    return c


def _delta_axis(recs: list, fig_dir: Path) -> list[str]:
    d = [r for r in recs if r["axis"] == "delta"]
    L = []
    for load in sorted({r["coords"]["load"] for r in d}):
        sub = [r for r in d if r["coords"]["load"] == load]
        ratio = sorted({(r["coords"]["delta"], r.get("stiffness_ratio")) for r in sub if r.get("stiffness_ratio")})
        extra = []
        if ratio:
            extra = ["Interface stiffness over elastic stiffness (max diagonal of the 1/delta part of K / max "
                     "diagonal of the elastic part), the source of ill-conditioning at small delta: "
                     + ", ".join(f"delta={_fmt(a)}: {b:.1e}" for a, b in ratio) + ".", ""]
        L += _section(fig_dir, sub, "delta", _solver_row, lambda r: r["coords"]["delta"], "solver", "delta",
                      "delta", extra, suffix=f"_{load}")
    return L


def _r_axis(recs: list, fig_dir: Path) -> list[str]:
    """Uzawa's r axis per solver, beside the solver's default (and its auto-r variants) from the delta axis."""
    d = [r for r in recs if r["axis"] == "delta"]
    rr = [r for r in recs if r["axis"] == "r"]
    L = []
    for s in sorted({r["solver"] for r in rr}):
        sub = [r for r in rr if r["solver"] == s]
        dflt = [_with_coords(r, r="default") for r in d if r["solver"] == s and r["coords"].get("load") == BASE["load"]]
        dparams = dflt[0].get("params_used", {}).get("r") if dflt else None
        # variants of the same method that choose r themselves (e.g. uzawa_auto), side by side
        variants = sorted({r["solver"] for r in d if r["solver"].startswith(s + "_")})
        for v in variants:
            dflt += [_with_coords(r, r=f"{v} (default)") for r in d
                     if r["solver"] == v and r["coords"].get("load") == BASE["load"]]
        extra = [f"Rows: r (stress per length); the row `default` is `{s}` with its default parameters "
                 f"(from the delta axis, {BASE['load']}{'' if dparams is None else ', r = ' + str(dparams)}); "
                 "the paper used r = 1e7 at every delta"
                 + (f"; the rows {', '.join('`' + v + ' (default)`' for v in variants)} are the variants that "
                    "choose r from the problem itself (their tolerance may differ)" if variants else "")
                 + ". The table below gives the outer iterations against r x delta "
                 "(dimensionless: the augmentation r compared with the interface stiffness 1/delta).", ""]
        _scatter_r_delta(sub, s, fig_dir / f"r_delta_{s}.png")
        extra += [f"![r x delta]({fig_dir.name}/r_delta_{s}.png)", "",
                  "Outer iterations of the correct runs against r x delta: "
                  + "; ".join(f"r delta = {_fmt(k)}: {', '.join(str(int(x)) for x in v)}"
                              for k, v in sorted(_by_product(sub).items())) + ".", ""]
        L += _section(fig_dir, sub + dflt, "r", lambda r: r["coords"]["r"], lambda r: r["coords"]["delta"], "r",
                      "delta", "delta", extra, suffix=f"_{s}")
    return L


def _other_axes(recs: list, fig_dir: Path) -> list[str]:
    def on(axis):
        return [r for r in recs if r["axis"] == axis]

    L = _section(fig_dir, on("units"), "units", _solver_row, lambda r: r["coords"]["units"], "solver",
                 "unit system", "units", [
                     "Unit systems relative to the paper's (MPa, length unit read as m): MPa-mm multiplies lengths "
                     "by 1e3, Pa-m stresses by 1e6, Pa-mm both, GPa-km divides both by 1e3. delta (a length per "
                     "stress) and the load are converted; the reference is the MPa-m reference mapped exactly. Rows "
                     "with `r=1e+07` keep the paper's number unconverted, to show what a fixed r does.", ""],
                 col_order=["MPa-m", "MPa-mm", "Pa-m", "Pa-mm", "GPa-km"])
    L += _section(fig_dir, on("load"), "load", _solver_row, lambda r: r["coords"]["load_scale"], "solver",
                  "load scale", "load scale",
                  ["The QP is positively homogeneous in the load: the reference is s x the reference at s = 1.", ""])
    L += _section(fig_dir, on("nu"), "nu", _solver_row, lambda r: r["coords"]["nu"], "solver", "nu", "nu",
                  ["P1 elements lock as nu -> 0.5 (lambda / mu = 2 nu / (1 - 2 nu) = 5000 at nu = 0.4999): the "
                   "discrete problem stays well posed but K's conditioning grows with lambda / mu.", ""])
    L += _section(fig_dir, on("N"), "N", _solver_row, lambda r: r["coords"]["N"], "solver", "N", "N",
                  ["Large N only for the solvers that fit the budgets: a solver is not attempted at 2N when its "
                   "time at N x 6 exceeds the per-run time limit, or its peak memory at N x 4.5 exceeds 80% of the "
                   "memory available at that moment (a shared machine), or it skipped N itself; the reason is in "
                   "each skipped run's record. An error of exactly 0 (blank in the error map) means a bit-for-bit "
                   "copy of the reference (e.g. a backend polished by the same active-set code), not an independent "
                   "check.", ""])
    return L


def base_scene(meta: dict) -> str:
    """The grid's base scene as its meta.json records it (``scene``: the --scene given, absent or
    "f2 (paper)" for the default; ``base``: its parameters): the name, and its mesh and delta."""
    name = meta.get("scene")
    if not name or name == "f2 (paper)":
        return (f"the paper's f2 (E = 69000, nu = 0.3, plane strain, delta = 1e-5) at N = "
                f"{16 if meta.get('quick') else 32}")
    base = meta.get("base") if isinstance(meta.get("base"), dict) else {}
    mesh = (f"gmsh, mesh_size = {base['mesh_size']:g}" if base.get("mesh") == "gmsh" and base.get("mesh_size")
            else f"N = {base['N']}" if base.get("N") else "its own mesh")
    keys = ", ".join(f"{k} = {base[k]:g}" for k in ("E", "nu", "delta") if isinstance(base.get(k), (int, float)))
    return f"`{name}` ({mesh}{', ' + keys if keys else ''})"


def render(meta: dict, recs: list, md_path: Path) -> str:
    """Write the figures next to ``md_path`` (folder ``stability/``) and return the Markdown text."""
    fig_dir = md_path.parent / "stability"
    L = _head(meta, recs) + _summary(recs) + correct_rate_section(recs)
    fig_dir.mkdir(parents=True, exist_ok=True)
    L += ["## The grid", "", f"Base scene: {base_scene(meta)}; each axis varies one thing. Per-run solver time "
          f"limit {meta.get('time_limit')} s.", ""]
    L += _delta_axis(recs, fig_dir) + _r_axis(recs, fig_dir) + _other_axes(recs, fig_dir)
    return "\n".join(L) + "\n"
