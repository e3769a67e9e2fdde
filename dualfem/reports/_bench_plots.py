"""The figures of ``dualfem report bench``: work-precision per scene identity and scaling per scene.

Work-precision: relative energy-norm error of x against time (setup + solve, seconds), log-log, one
column of panels per delta. Every run is a point (hollow when its status is not ``solved``). A solver
whose runs recorded convergence curves (:mod:`dualfem.reports._bench_curves`, error kind
``reference``: the same error as the points) is drawn as the median of the curves of its tightest
tier that has any, with the 25-75 % band when there are several curves; a solver without curves
joins its tier points by a thin line, as before curves existed. Horizontal dotted lines: the tiers'
tolerances; vertical dashed line: the floor (one factorization + one solve of K).

Legibility (:mod:`dualfem.post.style`): each solver keeps one Okabe-Ito colour + marker + line style
in every figure; a figure with more than :data:`~dualfem.post.style.MAX_SERIES` solvers gets one row
of panels per solver family (shared axes, one legend per row, right of the row); a smaller one a
single row with its legend below. No legend is drawn over data.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from dualfem.core.io import atomic_savefig
from dualfem.post.style import MAX_SERIES, Style, group_by_family, styles
from dualfem.reports._bench_curves import Curve, MedianCurve, median_curve
from dualfem.reports._bench_util import SceneId, _f, group_scenes, unknowns

#: font sizes of every bench figure (points)
RC = {"font.size": 9, "axes.titlesize": 9.5, "axes.labelsize": 9, "legend.fontsize": 8,
      "xtick.labelsize": 8, "ytick.labelsize": 8, "legend.title_fontsize": 8.5}
#: grey of the floor and tolerance guide lines (not a series colour)
GUIDE = "0.45"
#: colour of the reference solver's time line (not a series colour)
REF_LINE = "0.15"
#: errors below this are drawn at it
ERR_FLOOR = 1e-16
PANEL_W, PANEL_H = 3.3, 2.6


@dataclass(frozen=True)
class SolverCurve:
    """The median curve of one solver on one scene (the runs of its tier ``tier``)."""

    variant: str
    scene_key: str
    tier: str
    curve: MedianCurve


def facets(variants: Iterable[str]) -> list[tuple[str, list[str]]]:
    """Rows of panels: one row with every series when there are at most MAX_SERIES, else one row per
    solver family (:func:`dualfem.post.style.group_by_family`) as (family, members)."""
    variants = sorted(set(variants))
    if len(variants) <= MAX_SERIES:
        return [("", variants)]
    return list(group_by_family(variants).items())


def _tier_order(runs: list[dict]) -> dict[str, float]:
    """Tier name -> its tolerance (NaN for a tier without one: ``any``, tried last)."""
    out: dict[str, float] = {}
    for r in runs:
        out.setdefault(str(r["tier"]), _f(r.get("tol")))
    return out


def solver_curves(curves: list[Curve], runs: list[dict], kind: str = "reference") -> dict[tuple[str, str], SolverCurve]:
    """(variant, scene_key) -> the median curve of that solver's tightest tier with curves of ``kind``.
    A curve's variant and scene come from its run row (``run_id``), else from its own columns."""
    by_id = {str(r.get("run_id")): r for r in runs}
    tol = _tier_order(runs)
    groups: dict[tuple[str, str, str], list[Curve]] = {}
    for c in curves:
        if c.error_kind != kind:
            continue
        row = by_id.get(c.run_id)
        var = row["variant"] if row else c.solver
        sk = str(row.get("scene_key")) if row else c.scene_key
        groups.setdefault((var, sk, c.tier), []).append(c)
    out: dict[tuple[str, str], SolverCurve] = {}

    def tightness(tier: str) -> tuple[int, float]:
        t = tol.get(tier, float("nan"))
        return (0, t) if math.isfinite(t) else (1, 0.0)

    for (var, sk, tier) in sorted(groups, key=lambda k: (k[0], k[1], tightness(k[2]))):
        if (var, sk) not in out:
            out[(var, sk)] = SolverCurve(var, sk, tier, median_curve(groups[(var, sk, tier)]))
    return out


def selfref(r: dict) -> bool:
    """Whether a run is by its scene's reference solver: its error against that reference is 0 by
    construction, so it is drawn as a line at its time, not as a competitor's point."""
    return bool(r.get("ref_solver")) and str(r.get("ref_solver")) == str(r.get("solver"))


def _ref_time(pts: list[dict]) -> tuple[float, str] | None:
    """(median time [s], solver) of the reference solver's own runs among ``pts``, or None."""
    ts = sorted(_f(r.get("total_s")) for r in pts if selfref(r) and math.isfinite(_f(r.get("total_s"))))
    if not ts:
        return None
    return ts[len(ts) // 2], ", ".join(sorted({str(r["solver"]) for r in pts if selfref(r)}))


def _finite_points(pts: list[dict], var: str) -> list[dict]:
    vr = [r for r in pts if r["variant"] == var and not selfref(r) and math.isfinite(_f(r.get("err_x_energy")))
          and math.isfinite(_f(r.get("total_s")))]
    vr.sort(key=lambda r: -_f(r.get("tol")) if math.isfinite(_f(r.get("tol"))) else 0)
    return vr


def _draw_curve(ax, sc: SolverCurve, st: Style) -> None:
    import numpy as np

    c = sc.curve
    ok = np.isfinite(c.median)
    ax.plot(c.time_s[ok], np.maximum(c.median[ok], ERR_FLOOR), color=st.color, ls=st.linestyle, lw=1.6,
            alpha=0.95, zorder=3)
    if c.n_curves > 1:
        ax.fill_between(c.time_s[ok], np.maximum(c.low[ok], ERR_FLOOR), np.maximum(c.high[ok], ERR_FLOOR),
                        color=st.color, alpha=0.18, lw=0, zorder=2)


def _wp_panel(ax, pts: list[dict], members: list[str], st: dict[str, Style], floor_s: float | None,
              curves: dict[tuple[str, str], SolverCurve], tols: dict[str, float]) -> None:
    """One work-precision panel: the members' points, curves (or tier lines) and the guide lines (the
    floor; the reference solver's own runs, :func:`selfref`, as a line at their median time)."""
    for var in members:
        s = st[var]
        vr = _finite_points(pts, var)
        keys = {str(r.get("scene_key")) for r in pts if r["variant"] == var and not selfref(r)}
        sc = next((curves[(var, k)] for k in sorted(keys) if (var, k) in curves), None)
        if sc is not None:
            _draw_curve(ax, sc, s)
        elif len(vr) > 1:
            ax.plot([_f(r["total_s"]) for r in vr], [max(_f(r["err_x_energy"]), ERR_FLOOR) for r in vr],
                    color=s.color, ls=s.linestyle, lw=1.0, alpha=0.6, zorder=3)
        for r in vr:
            solved = r["status"] == "solved"
            ax.plot([_f(r["total_s"])], [max(_f(r["err_x_energy"]), ERR_FLOOR)], ls="none", marker=s.marker,
                    ms=5.5, color=s.color, mec=s.kwargs()["markeredgecolor"], mew=1.0,
                    mfc=s.color if solved else "none", zorder=4)
    if floor_s is not None and math.isfinite(floor_s):
        ax.axvline(floor_s, color=GUIDE, ls="--", lw=0.9, zorder=1)
    ref = _ref_time(pts)
    if ref is not None:
        ax.axvline(ref[0], color=REF_LINE, ls="-.", lw=1.1, zorder=1)
    for tol in tols.values():
        ax.axhline(tol, color=GUIDE, ls=":", lw=0.9, zorder=1)


def _legend_handles(members: list[str], st: dict[str, Style], curved: set[str], extra: list) -> list:
    from matplotlib.lines import Line2D

    h = [Line2D([], [], color=st[v].color, marker=st[v].marker, mec=st[v].kwargs()["markeredgecolor"],
                ls=st[v].linestyle, lw=1.6 if v in curved else 1.0, ms=5.5,
                label=v + (" (curve)" if v in curved else "")) for v in members]
    return h + extra


def _guides(floor: bool, tols: dict[str, float], ref: str = "") -> list:
    from matplotlib.lines import Line2D

    out = [Line2D([], [], color=GUIDE, ls="none", marker="o", mfc="none", ms=5.5, label="hollow: not solved")]
    if floor:
        out.append(Line2D([], [], color=GUIDE, ls="--", lw=0.9, label="floor: factor + solve K"))
    if ref:
        out.append(Line2D([], [], color=REF_LINE, ls="-.", lw=1.1, label=f"reference ({ref}): its own runs' time"))
    if tols:
        out.append(Line2D([], [], color=GUIDE, ls=":", lw=0.9,
                          label="tier tol: " + ", ".join(f"{k} {v:g}" for k, v in sorted(tols.items(),
                                                                                   key=lambda kv: -kv[1]))))
    return out


def _log_axes(ax, minor_labels: bool = True) -> None:
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    if ax.get_xscale() != "log":     # (setting it again would reset ticks a panel chose)
        ax.set_xscale("log")
    if ax.get_yscale() != "log":
        ax.set_yscale("log")
    lo, hi = ax.get_xlim()
    if minor_labels and hi < 10 * lo:     # within about one decade: label the minor ticks at 2, 3 and 5 x 10^k
        from matplotlib.ticker import FuncFormatter

        def minor(v: float, _pos) -> str:
            lead = round(v / 10 ** math.floor(math.log10(v))) if v > 0 else 0
            return f"{v:g}" if lead in (2, 3, 5) else ""

        ax.xaxis.set_minor_formatter(FuncFormatter(minor))
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
    else:
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="major", alpha=0.3)


def _grid(rows: list[tuple[str, list[str]]], ncols: int):
    import matplotlib.pyplot as plt

    legend_w = 2.3 if len(rows) > 1 else 0.0
    fig, axes = plt.subplots(len(rows), ncols, figsize=(PANEL_W * ncols + legend_w, PANEL_H * len(rows) + 0.6),
                             squeeze=False, sharex=True, sharey=True)
    return fig, axes


def _finish(fig, axes, rows, st, curved, guides, ylabel: str, title: str, figdir: Path, name: str,
            minor_labels: bool = True) -> str:
    """Row labels, legends outside the panels (per row when faceted, below otherwise), save."""
    import matplotlib.pyplot as plt

    for i, (fam, members) in enumerate(rows):
        axes[i][0].set_ylabel(f"{fam}\n{ylabel}" if fam else ylabel)
        for ax in axes[i]:
            _log_axes(ax, minor_labels)
        if len(rows) > 1:
            axes[i][-1].legend(handles=_legend_handles(members, st, curved, guides if i == 0 else []),
                               loc="upper left", bbox_to_anchor=(1.03, 1.0), borderaxespad=0.0, title=fam,
                               frameon=False)
    fig.suptitle(title, fontsize=10.5)
    fig.tight_layout()
    if len(rows) == 1:
        h = _legend_handles(rows[0][1], st, curved, guides)
        fig.legend(handles=h, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=min(len(h), 4), frameon=False)
    atomic_savefig(fig, figdir / name, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return name


def _present(sel: list[dict], curves: dict[tuple[str, str], SolverCurve]) -> list[str]:
    """The variants with something to draw in ``sel``: a finite point or a curve of one of its scenes."""
    keys = {str(r.get("scene_key")) for r in sel}
    out = {r["variant"] for r in sel if not selfref(r)
           and math.isfinite(_f(r.get("err_x_energy"))) and math.isfinite(_f(r.get("total_s")))}
    return sorted(out | {v for (v, k) in curves if k in keys and any(r["variant"] == v and not selfref(r)
                                                                      for r in sel)})


def wp_figure(sel: list[dict], deltas: list[float], floor_s: float | None, curves, title: str,
              figdir: Path, name: str) -> str:
    """One work-precision figure (``title``: the scene and its size): facets x deltas; returns the file name."""
    import matplotlib

    members = _present(sel, curves)
    rows = facets(members) or [("", [])]
    st = styles(members)
    tols = {k: v for k, v in _tier_order(sel).items() if math.isfinite(v) and v > 0}
    with matplotlib.rc_context(RC):
        fig, axes = _grid(rows, len(deltas))
        for j, d in enumerate(deltas):
            pts = [r for r in sel if _f(r.get("scene_delta")) == d or not math.isfinite(d)]
            for i, (_, mem) in enumerate(rows):
                _wp_panel(axes[i][j], pts, mem, st, floor_s, curves, tols)
            axes[0][j].set_title(f"delta = {d:g}")
            axes[-1][j].set_xlabel("time (setup + solve) [s]")
        curved = {v for (v, k) in curves if v in members and k in {str(r.get("scene_key")) for r in sel}}
        ref = _ref_time(sel)
        return _finish(fig, axes, rows, st, curved, _guides(floor_s is not None, tols, ref[1] if ref else ""),
                       "rel. energy-norm error of x", f"work-precision: {title}", figdir, name)


def _scaling_panel(ax, sel: list[dict], members: list[str], st: dict[str, Style], floor_t: dict, d: float) -> None:
    """One scaling panel: time of the tightest solved tier against the unknowns, with the floor."""
    for var in members:
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
            s = st[var]
            ax.plot(ns, [pts[n][0] for n in ns], color=s.color, ls=s.linestyle, marker=s.marker, ms=5,
                    mec=s.kwargs()["markeredgecolor"], lw=1.2)
    ns = sorted({_f(r.get("n_unknowns")) for r in sel if math.isfinite(_f(r.get("n_unknowns")))})
    if ns:      # label the measured sizes only (the default minor labels crowd a short log axis)
        from matplotlib.ticker import NullFormatter

        ax.set_xscale("log")
        ax.set_xticks(ns, [f"{n:g}" for n in ns])
        ax.xaxis.set_minor_formatter(NullFormatter())
    if floor_t:
        fl = sorted(floor_t.values())
        ax.plot([a for a, _, _ in fl], [b for _, b, _ in fl], color=GUIDE, ls="--", lw=1.2)
        ax.plot([a for a, _, _ in fl], [1.5 * b for _, b, _ in fl], color=GUIDE, ls=":", lw=0.9)


def scaling_figure(sel: list[dict], deltas: list[float], floor_t: dict, load: str, figdir: Path, name: str) -> str:
    """One scaling figure (scene ``load``): facets x deltas; returns the file name."""
    import matplotlib
    from matplotlib.lines import Line2D

    members = sorted({r["variant"] for r in sel if r["status"] == "solved"
                      and math.isfinite(_f(r.get("total_s")))})
    rows = facets(members) or [("", [])]
    st = styles(members)
    guides = ([Line2D([], [], color=GUIDE, ls="--", lw=1.2, label="floor: factor + solve K"),
               Line2D([], [], color=GUIDE, ls=":", lw=0.9, label="1.5 x floor")] if floor_t else [])
    with matplotlib.rc_context(RC):
        fig, axes = _grid(rows, len(deltas))
        for j, d in enumerate(deltas):
            for i, (_, mem) in enumerate(rows):
                _scaling_panel(axes[i][j], sel, mem, st, floor_t, d)
            axes[0][j].set_title(f"delta = {d:g}")
            axes[-1][j].set_xlabel("unknowns")
        return _finish(fig, axes, rows, st, set(), guides, "time [s], tightest solved tier",
                       f"scaling: {load}", figdir, name, minor_labels=False)


@dataclass(frozen=True)
class Figure:
    """One drawn figure: its file name (in the figure folder), what it shows and its median unknowns."""

    name: str
    scene: SceneId
    n_unknowns: float


def _floors(floors: list[dict]) -> dict[float, tuple[float, float, str]]:
    """Unknowns -> (unknowns, time [s], backend) of every usable floor row (a floor is K's size)."""
    return {_f(f.get("n_unknowns")): (_f(f.get("n_unknowns")), _f(f.get("total_s")), str(f.get("solver")))
            for f in floors if f.get("status") in ("solved", "inaccurate") and math.isfinite(_f(f.get("n_unknowns")))}


def plots(runs: list[dict], floors: list[dict], figdir: Path,
          curves: list[Curve] | None = None) -> tuple[list[Figure], list[Figure]]:
    """Draw every figure into ``figdir``; returns (work-precision figures, scaling figures).

    One work-precision figure per scene identity (:func:`dualfem.reports._bench_util.group_scenes`: the
    scene's name and the values of its grid keys that vary, e.g. ``N`` or ``mesh_size``), one panel
    column per delta; one scaling figure per scene name that was run at two sizes or more. The floor of
    a figure is the floor row of the same number of unknowns. ``curves``: the sweep's convergence
    curves (those of error kind ``reference`` are drawn)."""
    import matplotlib

    matplotlib.use("Agg")
    figdir.mkdir(parents=True, exist_ok=True)
    floor_t = _floors(floors)
    deltas = sorted({_f(r.get("scene_delta")) for r in runs if math.isfinite(_f(r.get("scene_delta")))},
                    reverse=True)
    has = [r for r in runs if r["status"] != "skipped"]
    med = solver_curves(curves or [], has)
    wp_files, sc_files = [], []
    by_scene: dict[str, list[dict]] = {}
    for sid, sel in group_scenes(has).items():     # work-precision: one panel column per delta
        ds = [d for d in deltas if any(_f(r.get("scene_delta")) == d for r in sel)] or [float("nan")]
        n = unknowns(sel)
        fl = floor_t[n][1] if n in floor_t else None
        title = sid.label + (f" ({n:,.0f} unknowns)" if math.isfinite(n) else "")
        wp_files.append(Figure(wp_figure(sel, ds, fl, med, title, figdir, f"wp_{sid.slug}.png"), sid, n))
        by_scene.setdefault(sid.scene, []).extend(sel)
    for name, sel in by_scene.items():     # scaling: one figure per scene name, one panel column per delta
        ns = {_f(r.get("n_unknowns")) for r in sel if math.isfinite(_f(r.get("n_unknowns")))}
        ds = [d for d in deltas if any(_f(r.get("scene_delta")) == d for r in sel)]
        if not ds or len(ns) < 2:
            continue
        fl = {k: v for k, v in floor_t.items() if k in ns}
        sid = SceneId(name)
        sc_files.append(Figure(scaling_figure(sel, ds, fl, name, figdir, f"scaling_{sid.slug}.png"), sid,
                               max(ns)))
    return wp_files, sc_files
