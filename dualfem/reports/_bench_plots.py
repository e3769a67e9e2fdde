"""The figures of ``dualfem report bench``: work-precision per (scene, N) and scaling per scene."""
from __future__ import annotations

import math
from pathlib import Path

from dualfem.core.io import atomic_savefig
from dualfem.reports._bench_util import _f


def save_with_legend(fig, axes, figdir, name: str) -> str:
    """One legend for all panels (labels de-duplicated), saved as figdir/name; returns name."""
    import matplotlib.pyplot as plt

    h, lab = [], []
    for ax in axes:
        for hh, ll in zip(*ax.get_legend_handles_labels()):
            if ll not in lab:
                h.append(hh)
                lab.append(ll)
    fig.legend(h, lab, loc="upper center", ncol=min(len(lab), 8), fontsize=8, bbox_to_anchor=(0.5, 1.08))
    fig.tight_layout()

    atomic_savefig(fig, figdir / name, dpi=90, bbox_inches="tight")
    plt.close(fig)
    return name


def _wp_panel(ax, pts: list[dict], variants, color, floor_t: dict, load: str, N: float, d: float) -> None:
    """One work-precision panel: error against time, one curve per variant through its tiers."""
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    for var in variants:
        vr = [r for r in pts if r["variant"] == var and math.isfinite(_f(r.get("err_x_energy")))
              and math.isfinite(_f(r.get("total_s")))]
        if not vr:
            continue
        vr.sort(key=lambda r: -_f(r.get("tol")) if math.isfinite(_f(r.get("tol"))) else 0)
        x = [_f(r["total_s"]) for r in vr]
        y = [max(_f(r["err_x_energy"]), 1e-16) for r in vr]
        ax.plot(x, y, "-", color=color[var], lw=1, alpha=0.7)
        for r, xi, yi in zip(vr, x, y):
            ok = r["status"] == "solved"
            ax.plot([xi], [yi], "o", color=color[var], mfc=color[var] if ok else "none",
                    label=var if r is vr[0] else None)
    if N in floor_t:
        ax.axvline(floor_t[N][1], color="k", ls="--", lw=0.8, label="floor")
    ax.set_xscale("log")
    ax.set_yscale("log")
    lo, hi = ax.get_xlim()
    if hi < 10 * lo:     # within one decade: no major tick, so label the minor ones
        ax.xaxis.set_minor_formatter(FormatStrFormatter("%g"))
    else:
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_title(f"{load} N={N:g} delta={d:g}", fontsize=9)
    ax.set_xlabel("time (setup + solve) [s]")
    ax.grid(True, which="major", alpha=0.3)


def _scaling_panel(ax, sel: list[dict], variants, color, floor_t: dict, load: str, d: float) -> None:
    """One scaling panel: time of the tightest solved tier against the unknowns, with the floor."""
    from matplotlib.ticker import NullFormatter

    for var in variants:
        pts = {}
        for r in sel:
            if r["variant"] != var or _f(r.get("scene_delta")) != d or r["status"] != "solved":
                continue
            n, t, tol = _f(r.get("n_unknowns")), _f(r.get("total_s")), _f(r.get("tol"))
            tol = tol if math.isfinite(tol) else 0.0
            if n not in pts or tol < pts[n][1]:     # the tightest solved tier
                pts[n] = (t, tol)
        if pts:
            ns = sorted(pts)
            ax.plot(ns, [pts[n][0] for n in ns], "o-", color=color[var], label=var, ms=4)
    if floor_t:
        fl = sorted(floor_t.values())
        ax.plot([a for a, _, _ in fl], [b for _, b, _ in fl], "k--", lw=1.2, label="floor: factor+solve K")
        ax.plot([a for a, _, _ in fl], [1.5 * b for _, b, _ in fl], "k:", lw=0.8, label="1.5 x floor")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_title(f"{load} delta={d:g}", fontsize=9)
    ax.set_xlabel("unknowns")
    ax.grid(True, which="major", alpha=0.3)


def plots(runs, floors, figdir: Path) -> tuple[list[str], list[str]]:
    """Draw every figure into ``figdir``; returns (work-precision files, scaling files)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figdir.mkdir(parents=True, exist_ok=True)
    variants = sorted({r["variant"] for r in runs})
    cmap = plt.get_cmap("tab10")
    color = {v: cmap(i % 10) for i, v in enumerate(variants)}
    floor_t = {_f(f.get("scene_N")): (_f(f["n_unknowns"]), _f(f["total_s"]), f["solver"])
               for f in floors if f["status"] in ("solved", "inaccurate")}
    loads = sorted({str(r["scene"]) for r in runs})
    Ns = sorted({_f(r.get("scene_N")) for r in runs if math.isfinite(_f(r.get("scene_N")))})
    deltas = sorted({_f(r.get("scene_delta")) for r in runs if math.isfinite(_f(r.get("scene_delta")))},
                    reverse=True)
    wp_files, sc_files = [], []
    has = [r for r in runs if r["status"] != "skipped"]
    for load in loads:     # work-precision: one figure per (scene, N), one panel per delta
        for N in Ns:
            sel = [r for r in has if r["scene"] == load and _f(r.get("scene_N")) == N]
            if not sel:
                continue
            ds = [d for d in deltas if any(_f(r.get("scene_delta")) == d for r in sel)] or [float("nan")]
            fig, axes = plt.subplots(1, len(ds), figsize=(3.6 * len(ds), 3.4), squeeze=False, sharey=True)
            for ax, d in zip(axes[0], ds):
                pts = [r for r in sel if _f(r.get("scene_delta")) == d or not math.isfinite(d)]
                _wp_panel(ax, pts, variants, color, floor_t, load, N, d)
            axes[0][0].set_ylabel("relative energy-norm error of x")
            wp_files.append(save_with_legend(fig, axes[0], figdir, f"wp_{load}_N{int(N)}.png"))
    for load in loads:     # scaling: one figure per scene, one panel per delta
        sel = [r for r in has if r["scene"] == load]
        ds = [d for d in deltas if any(_f(r.get("scene_delta")) == d for r in sel)]
        if not ds or len(Ns) < 2:
            continue
        fig, axes = plt.subplots(1, len(ds), figsize=(3.6 * len(ds), 3.4), squeeze=False, sharey=True)
        for ax, d in zip(axes[0], ds):
            _scaling_panel(ax, sel, variants, color, floor_t, load, d)
        axes[0][0].set_ylabel("time (setup + solve) [s], tightest solved tier")
        sc_files.append(save_with_legend(fig, axes[0], figdir, f"scaling_{load}.png"))
    return wp_files, sc_files
