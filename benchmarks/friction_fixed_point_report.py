"""Render reports/friction_fixed_point.md and its figures (friction_fixed_point/*.png) from
benchmarks/results/friction_fixed_point/friction_fixed_point.json (benchmarks/friction_fixed_point.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

COMMAND = ("nice -n 10 python benchmarks/friction_fixed_point.py --out benchmarks/results/friction_fixed_point "
           "--report reports")


def _f(v, fmt=".3f") -> str:
    return "-" if v is None else format(v, fmt)


def _its(it: dict) -> str:
    return ", ".join(f"{k} {v}" for k, v in it.items())


def _solvers(rows: list[dict]) -> list[str]:
    return list(dict.fromkeys(r["solver"] for r in rows))


def steps_table(rows: list[dict], dim: int) -> list[str]:
    """mu_f down, solver across: fixed-point steps (Tresca solves) and the observed contraction; for the solvers
    without the fixed point their own counters; a status other than solved is written beside the number."""
    rows = [r for r in rows if r["dim"] == dim]
    if not rows:
        return []
    names = _solvers(rows)
    by = {(r["mu_f"], r["solver"]): r for r in rows}
    out = [f"| mu_f | {' | '.join(names)} |", "|---|" + "---|" * len(names)]
    for mu in sorted({r["mu_f"] for r in rows}):
        cells = []
        for s in names:
            r = by.get((mu, s))
            if r is None:
                cells.append("")
                continue
            if "steps" in r:
                cell = f"{r['steps']}, rho {_f(r.get('contraction'), '.3f')}"
            else:
                cell = _its(r["iterations"])
            if r["status"] != "solved":
                cell += f" ({r['status']})"
            cells.append(cell)
        out.append(f"| {mu:g} | {' | '.join(cells)} |")
    return out


def detail_table(rows: list[dict], dim: int) -> list[str]:
    out = ["| mu_f | solver | status | certified error | setup s | solve s | iterations | changes of the threshold |",
           "|---|---|---|---|---|---|---|---|"]
    for r in (r for r in rows if r["dim"] == dim):
        ch = ", ".join(f"{c:.0e}" for c in r.get("changes", [])) or "-"
        out.append(f"| {r['mu_f']:g} | {r['solver']} | {r['status']} | {_f(r['certified'], '.1e')} | "
                   f"{_f(r['setup_s'])} | {_f(r['solve_s'])} | {_its(r['iterations'])} | {ch} |")
    return out


def findings(rows: list[dict]) -> list[str]:
    """Lines computed from the data: per scene, the fixed-point steps' range per solver, the contraction's
    growth with mu_f (least squares through the origin over the fixed-point runs that solved), the statuses
    that are not solved."""
    out = []
    for dim in (2, 3):
        rs = [r for r in rows if r["dim"] == dim]
        if not rs:
            continue
        fp = [r for r in rs if "steps" in r and r["status"] == "solved" and r.get("contraction") is not None]
        parts = []
        for s in _solvers([r for r in rs if "steps" in r]):
            st = [r["steps"] for r in rs if r["solver"] == s and "steps" in r]
            parts.append(f"{s} {min(st)}-{max(st)}" if min(st) != max(st) else f"{s} {st[0]}")
        line = f"- {dim}D ({rs[0]['n']:,} unknowns, {rs[0]['nodes']} friction nodes): Tresca solves of the fixed " \
               f"point for mu_f {min(r['mu_f'] for r in rs):g} ... {max(r['mu_f'] for r in rs):g}: " + "; ".join(parts)
        if fp:
            mu = np.array([r["mu_f"] for r in fp])
            rho = np.array([r["contraction"] for r in fp])
            slope = float(mu @ rho / (mu @ mu))
            line += (f". Observed contraction {rho.min():.3f} ... {rho.max():.3f}, about {slope:.3f} mu_f (least "
                     "squares through 0)")
        bad = [f"{r['solver']} at mu_f {r['mu_f']:g}: {r['status']}" for r in rs if r["status"] != "solved"]
        out.append(line + ("; not solved: " + "; ".join(bad) if bad else "; every run solved and certified") + ".")
    return out


def _handles(axes) -> tuple[list, list]:
    """(handles, labels) of the labelled series of ``axes``, each label once."""
    hs, ls = [], []
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in ls:
                hs.append(h)
                ls.append(lab)
    return hs, ls


def _figure_steps(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dualfem.post.style import styles

    names = _solvers([r for r in rows if "steps" in r])
    st = styles(names)
    fig, axes = plt.subplots(2, 2, figsize=(13, 7), squeeze=False)
    for col, dim in enumerate((2, 3)):
        for s in names:
            rs = [r for r in rows if r["dim"] == dim and r["solver"] == s and "steps" in r]
            if not rs:
                continue
            kw = st[s].kwargs()
            axes[0][col].plot([r["mu_f"] for r in rs], [r["steps"] for r in rs], label=s, **kw)
            ok = [r for r in rs if r.get("contraction") is not None]
            axes[1][col].plot([r["mu_f"] for r in ok], [r["contraction"] for r in ok], label=s, **kw)
            bad = [r for r in rs if r["status"] != "solved"]
            axes[0][col].plot([r["mu_f"] for r in bad], [r["steps"] for r in bad], "x", color="k", ms=9)
        axes[0][col].set_title(f"{dim}D: Tresca solves of the fixed point (x: not solved)", fontsize=9)
        axes[1][col].set_title(f"{dim}D: observed contraction (largest ratio of successive changes)", fontsize=9)
        axes[1][col].set_xlabel("mu_f")
        for ax in axes[:, col]:
            ax.grid(True, alpha=0.3)
    hs, ls = _handles(axes[0])
    if hs:
        fig.legend(hs, ls, fontsize=7, loc="center right", frameon=False)
    fig.tight_layout(rect=(0, 0, 0.78, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _figure_maps(maps: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dualfem.post.style import FIELD_CMAP, PALETTE

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.4))
    for ax, m in zip(axes, maps):
        if "slip" not in m:
            ax.set_title(f"{m['dim']}D: {m['status']} (no answer)")
            continue
        slip, stick = np.asarray(m["slip"]), np.asarray(m["stick"], bool)
        if m["dim"] == 2:
            s = np.asarray(m["s"])
            order = np.argsort(s)
            ax.plot(s[order], slip[order], "-", color=PALETTE[0], lw=0.8)
            ax.plot(s[~stick], slip[~stick], "o", color=PALETTE[0], ms=4, label="slip")
            ax.plot(s[stick], slip[stick], "x", color=PALETTE[1], ms=7, label="stick")
            ax2 = ax.twinx()
            ax2.plot(s[order], np.asarray(m["g"])[order], "--", color=PALETTE[2], lw=1, label="threshold g")
            ax2.axhline(m["tau"], color=PALETTE[4], lw=0.8, ls=":", label="shear tau")
            ax2.set_ylabel("g, tau (stress)")
            ax2.legend(fontsize=7, loc="upper right")
            ax.set_xlabel("position along the crack (from its centre)")
            ax.set_ylabel("slip |[u_t]|")
            ax.legend(fontsize=7, loc="upper left")
            ax.set_title(f"2D crack at 30 deg, Tresca g = {m['expr']}", fontsize=8)
        else:
            px, py = np.asarray(m["px"]), np.asarray(m["py"])
            sc = ax.scatter(px[~stick], py[~stick], c=slip[~stick], cmap=FIELD_CMAP, s=16)
            ax.scatter(px[stick], py[stick], marker="x", color="k", s=16, label="stick")
            ax.add_patch(plt.Circle((0, 0), 1.0, fill=False, lw=0.8))
            ax.set_aspect("equal")
            if (~stick).any():
                fig.colorbar(sc, ax=ax, shrink=0.8, label="slip length")
            ax.legend(fontsize=7, loc="lower right")
            ax.set_title(f"penny, Tresca g = {m['expr']}", fontsize=8)
    fig.suptitle("Stick and slip under a threshold that grows across the defect (pdas, certified)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _map_lines(maps: list[dict]) -> list[str]:
    out = []
    for m in maps:
        where = "along the crack" if m["dim"] == 2 else "over the disk"
        if "stick" not in m:
            out.append(f"- {m['dim']}D: {m['status']} (no answer to map).")
            continue
        stick = np.asarray(m["stick"], bool)
        g = np.asarray(m["g"])
        gs = f"g {g[stick].min():.2f} ... {g[stick].max():.2f}" if stick.any() else "none"
        out.append(f"- {m['dim']}D ({m['n']:,} unknowns), Tresca g = `{m['expr']}`, tau = {m['tau']:g}: status "
                   f"{m['status']}, certified error {_f(m['certified'], '.1e')}; {int(stick.sum())} of {stick.size} "
                   f"nodes stick {where} (their thresholds: {gs}), {int((~stick).sum())} slip (largest slip "
                   f"{np.max(np.asarray(m['slip'])):.2e}).")
    return out


def render(data: dict, report: Path) -> Path:
    """Write ``report/friction_fixed_point.md`` and ``report/friction_fixed_point/{steps,stick_slip}.png``."""
    figdir = report / "friction_fixed_point"
    figdir.mkdir(parents=True, exist_ok=True)
    rows, maps = data["sweep"], data["maps"]
    _figure_steps(rows, figdir / "steps.png")
    _figure_maps(maps, figdir / "stick_slip.png")
    m = data.get("machine", {})
    md = ["# Coulomb friction by the fixed point against mu_f, and stick/slip maps", "",
          f"Generated by `{COMMAND}` (`--render-only` re-renders from "
          "`benchmarks/results/friction_fixed_point/friction_fixed_point.json`)"
          + (" with `--quick` (coarse meshes, a few mu_f: a smoke test)" if data.get("quick") else "")
          + f". {data.get('date', '')}; machine {m.get('cpu', m.get('processor', '?'))}, "
          f"{m.get('cores', m.get('cpu_count', '?'))} cores shared with other jobs (load {data.get('load_before')} "
          f"before, {data.get('load_after')} after); one run each: read counts, not seconds. Part of the friction "
          "study: [friction.md](friction.md).", "",
          "The 2D inclined closed crack of the friction study (30 degrees) and its penny, each under a remote stress "
          "that puts pressure sigma_n = 1 and shear tau = 1.2 on the crack plane (slip for every mu_f below 1.2), "
          "Coulomb mu_f on the defect. The fixed point g <- mu_f lambda_nu over Tresca solves "
          "(`dualfem.numerics.coulomb`) is what pdas (`coulomb=fixed_point`), mprgp, penalty, uzawa_auto "
          "(`coulomb=fixed_point`), clarabel, cvxpy and osqp do; pdas (default: the radius mu_f lambda inside the "
          "semismooth Newton system) and uzawa / uzawa_auto (default: the threshold updated inside the Uzawa loop) "
          "are the monolithic comparison. rho = the observed contraction, the largest ratio of successive relative "
          "changes of the threshold (from the second step on). The step counts differ between solvers by their own "
          "stop rule of the fixed point (relative change of the threshold: pdas 1e-11, mprgp 1e-11, clarabel and "
          "cvxpy 1e-10, osqp 1e-8, uzawa_auto 10 tol, penalty max(100 tol, 1e-8)), not by the map, which is the "
          "same for all (the same rho). Every answer certified by the runner (status column of the detail "
          "tables).", "",
          "## Findings", "", *findings(rows), "",
          "![fixed-point steps and contraction against mu_f](friction_fixed_point/steps.png)", ""]
    for dim in (2, 3):
        t = steps_table(rows, dim)
        if t:
            md += [f"## {dim}D: fixed-point steps (rho) per solver; the others' own counters", "", *t, ""]
    md += ["## Stick/slip maps", "",
           "Tresca with a threshold that grows across the defect, so that part of it sticks: the 2D crack under "
           "sigma_n = 1, tau = 0.5 with g rising from 0.2 to 0.8 along it, the penny under the same traction with "
           "g = 0.5 + 0.4 (x - 5) (0.1 ... 0.9 across the disk). A node slips when its slip exceeds the "
           "evaluator's contact tolerance (the one of `dualfem solve`'s friction line).", "", *_map_lines(maps), "",
           "![stick and slip](friction_fixed_point/stick_slip.png)", ""]
    for dim in (2, 3):
        if any(r["dim"] == dim for r in rows):
            md += [f"## {dim}D: every run", "", *detail_table(rows, dim), ""]
    path = report / "friction_fixed_point.md"
    path.write_text("\n".join(md) + "\n")
    return path
