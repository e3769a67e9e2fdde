"""Figures of a thin-defect solution (the paper's Figs 2-7 and convergence histories).

Every function draws from the library's own objects, ``qp`` (a scene's QP: it carries the mesh
maps and the material) and a :class:`~dualfem.solution.Solution`, on a matplotlib ``Axes``
(a new figure when ``ax`` is None), and returns the ``Axes``; the same calls work in a
notebook::

    from dualfem.core.scene import load_scene
    from dualfem.experiments.runner import run
    from dualfem.post import figures
    qp = load_scene("f2", {"N": 64, "delta": 1e-1}).build()
    sol = run(figures.pick_solver(), qp)
    figures.plot_deformed(qp, sol, scale=300)

matplotlib is imported lazily, so importing this module is cheap.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.registry import get_solver, solvers
from dualfem.core.solver import reference_solvers
from dualfem.post.fields import Post, defect_stretches
from dualfem.post.style import FIELD_CMAP, PALETTE

#: the colours of line series (the Okabe-Ito palette without its light yellow)
LINE_COLORS = PALETTE[:-1]
#: colours of the two faces of a defect (upper +, lower -) and of the closed-node markers
UPPER, LOWER, CLOSED = PALETTE[1], PALETTE[0], PALETTE[1]


def pick_solver(name: str | None = None, *, exact: bool = True, order: Sequence[str] | None = None) -> str:
    """Name of the solver to use: ``name`` if given (checked), else the first registered and
    installed solver of ``order`` (with ``exact`` True, only solvers declaring ``exact``); without
    ``order``, the reference solvers in their declared order (``Solver.reference``,
    :func:`dualfem.core.solver.reference_solvers`)."""

    if name is not None:
        cls = get_solver(name)
        if cls.missing():
            raise InputError(cls.missing())
        return name
    reg = solvers()
    if order is None:
        order = [n for n, _ in reference_solvers(reg)]
    for n in order:
        cls = reg.get(n)
        if cls is not None and cls.missing() is None and (cls.exact or not exact):
            return n
    raise InputError(f"none of the solvers {', '.join(order) or '(no reference solver declared)'} "
                     "is registered and installed")


def _axes(ax, figsize=(6.4, 4.8), lines: bool = False):
    """``ax``, or a new figure's; ``lines``: its line colours cycle through :data:`LINE_COLORS`."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=figsize)
    if lines:
        ax.set_prop_cycle(color=list(LINE_COLORS))
    return ax


def _post(qp, sol) -> Post:
    return sol if isinstance(sol, Post) else Post(qp, sol)


def _units(qp) -> str:
    return str((getattr(qp, "params", {}) or {}).get("units", "MPa"))


def _along(post: Post) -> tuple[np.ndarray, str]:
    """Abscissa along the defect: x1 for a horizontal defect (as in the paper), else s."""
    d = post.defect
    tau = np.asarray(post.qp.maps.get("tangent", (1.0, 0.0)), dtype=float)
    if "tangent" in post.qp.maps or getattr(post.qp, "interface", None) is None:
        if abs(abs(tau[0]) - 1) < 1e-12:
            return d["X"][0], "x1"
    return d["s"], "s (distance from the defect's first tip)"


def _stretches(post: Post, label: str):
    """(label, index array, abscissa) per defect: one curve per defect when there are several."""

    x, xlabel = _along(post)
    parts = defect_stretches(post.defect)
    if len(parts) == 1:
        return [(label, parts[0], x[parts[0]])], xlabel
    return [(f"{label}, defect {int(post.defect['defect_id'][i[0]])}", i, x[i]) for i in parts], xlabel


def plot_deformed(qp, sol, ax=None, *, scale: float = 300.0, title: str | None = None, vmax: float | None = None,
                  cmap: str = FIELD_CMAP, colorbar: bool = True, edges: bool = False, reference: bool = False,
                  contact: bool = False, labels: bool = False):
    """The deformed body X + scale u, triangles coloured by the von Mises stress (colour bar in
    the units of E; ``cmap`` default :data:`dualfem.post.style.FIELD_CMAP`, viridis: the stress is
    >= 0, no sign to show); the faces of every defect are drawn in white outlined in black on top
    (legible on every colour of the map), each defect on its own (tips included). ``reference``: each
    defect's undeformed line too (black, dashed);
    ``contact``: the closed nodes (evaluator contact set) marked on the deformed lower face;
    ``labels``: each defect's number (``[[defects]]`` order, from 0) beside its first tip."""
    ax = _axes(ax)
    p = _post(qp, sol)
    xy = p.deformed(scale)
    vm = p.von_mises
    coll = ax.tripcolor(xy[0], xy[1], p.triangles.T, facecolors=vm, cmap=cmap, vmin=0.0,
                        vmax=vmax if vmax is not None else float(vm.max()),
                        edgecolors="k" if edges else "none", linewidth=0.1 if edges else 0.0)
    if getattr(qp, "interface", None) is not None:
        _draw_defects(ax, qp, p, xy, reference=reference, contact=contact, labels=labels)
    if colorbar:
        ax.figure.colorbar(coll, ax=ax, label=f"von Mises stress [{_units(qp)}]")
    ax.set_aspect("equal")
    ax.set_xlabel(f"x1 + {scale:g} u1")
    ax.set_ylabel(f"x2 + {scale:g} u2")
    if title:
        ax.set_title(title, fontsize=10)
    return ax


def _draw_defects(ax, qp, p: Post, xy: np.ndarray, *, reference: bool, contact: bool, labels: bool) -> None:
    """Both faces of each defect (white), optionally its undeformed line, closed nodes and number."""

    from matplotlib import patheffects

    d = p.defect
    closed = None
    outline = [patheffects.withStroke(linewidth=2.0, foreground="k")]
    if contact:

        closed = np.zeros(d["s"].size, dtype=bool)
        closed[d["interior"]] = evaluator.contact_set(qp, p.x)[d["row"][d["interior"]]]
    for n, idx in enumerate(defect_stretches(d)):
        for ids in (d["upper"][idx], d["lower"][idx]):
            ax.plot(xy[0, ids], xy[1, ids], "w-", lw=0.8, path_effects=outline)
        if reference:
            ax.plot(d["X"][0, idx], d["X"][1, idx], "k--", lw=0.6, label="undeformed defect" if n == 0 else None)
        if closed is not None and closed[idx].any():
            c = d["lower"][idx][closed[idx]]
            ax.plot(xy[0, c], xy[1, c], "o", ms=3, mfc=CLOSED, mec="k", mew=0.4, ls="none",
                    label="closed nodes (contact)" if not any(ln.get_label().startswith("closed")
                                                              for ln in ax.get_lines()) else None)
        if labels:
            k = int(d["defect_id"][idx[0]])
            ax.annotate(str(k), xy[:, d["lower"][idx[0]]], xytext=(-4, 3), textcoords="offset points",
                        ha="right", fontsize=8, color="k", fontweight="bold",
                        bbox={"boxstyle": "round,pad=0.15", "fc": "w", "alpha": 0.75, "lw": 0})
    if reference or contact:
        ax.legend(fontsize=7, loc="lower left", framealpha=0.7)


def plot_jump(cases: Iterable[tuple[str, object, object]], ax=None, *, unit: float = 1e-5, component: str = "normal",
              log: bool = False, floor: float = 1e-16):
    """Jump [u_nu] (or [u_tau]) along the defect for several solutions; ``cases`` are
    ``(label, qp, sol)``; values are plotted in multiples of ``unit`` (paper: 1e-5), or with
    ``log=True`` as they are on a log scale (values below ``floor``, e.g. closed nodes, drawn
    at the floor)."""
    ax = _axes(ax, lines=True)
    key = {"normal": "jump_normal", "tangent": "jump_tangent"}.get(component)
    if key is None:
        raise InputError(f"component must be 'normal' or 'tangent', got {component!r}")
    xlabel = "s"
    for label, qp, sol in cases:
        p = _post(qp, sol)
        series, xlabel = _stretches(p, label)
        for lab, idx, x in series:
            y = p.defect[key][idx]
            if log:
                ax.semilogy(x, np.maximum(np.abs(y), floor), ".-", ms=3, lw=1, label=lab)
            else:
                ax.plot(x, y / unit, ".-", ms=3, lw=1, label=lab)
    sym = "[u_nu]" if component == "normal" else "[u_tau]"
    ax.set_xlabel(xlabel)
    if log:
        ax.set_ylim(bottom=floor * 1e3 if floor > 0 else None)
        ax.set_ylabel(f"|{sym}| (log scale; closed nodes at the bottom)")
    else:
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(f"{sym} / {unit:g}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return ax


def plot_faces(qp, sol, ax=None, *, scale: float = 300.0, title: str | None = None):
    """Shapes of the upper and lower faces of the defect, X + scale u, with the undeformed defect."""
    ax = _axes(ax)
    p = _post(qp, sol)

    d = p.defect
    for n, idx in enumerate(defect_stretches(d)):     # each defect on its own
        X = d["X"][:, idx]
        for key, color, label in (("u_upper", UPPER, "upper face (+)"), ("u_lower", LOWER, "lower face (-)")):
            ax.plot(X[0] + scale * d[key][idx, 0], X[1] + scale * d[key][idx, 1], ".-", color=color, ms=3, lw=1,
                    label=label if n == 0 else None)
        ax.plot(X[0], X[1], "k--", lw=0.7, label="undeformed" if n == 0 else None)
    ax.set_xlabel(f"x1 + {scale:g} u1")
    ax.set_ylabel(f"x2 + {scale:g} u2")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return ax


def plot_pressure(cases: Iterable[tuple[str, object, object]], ax=None):
    """Contact pressure l = mu / w (units of E) along the defect; ``cases`` are ``(label, qp, sol)``."""
    ax = _axes(ax, lines=True)
    xlabel, units = "s", "MPa"
    for label, qp, sol in cases:
        p = _post(qp, sol)
        if p.multipliers is None:
            raise InputError(f"case {label!r} has no multipliers")
        series, xlabel = _stretches(p, label)
        units = _units(qp)
        for lab, idx, x in series:
            ax.plot(x, p.defect["pressure"][idx], ".-", ms=3, lw=1, label=lab)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"contact pressure mu/w [{units}]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return ax


def history_series(sol, key: str) -> tuple[np.ndarray, np.ndarray] | None:
    """(iteration numbers, values) of ``key`` in ``sol.history``, or None if it has none."""
    hist = getattr(sol, "history", None) or []
    rows = [h for h in hist if isinstance(h, dict) and key in h and h[key] is not None]
    if not rows:
        return None
    it = np.array([h.get("k", h.get("iter", i + 1)) for i, h in enumerate(rows)], dtype=float)
    return it, np.array([float(h[key]) for h in rows])


def plot_history(runs: Iterable[tuple], ax=None, *, key: str | Sequence[str] = "dual_change",
                 ylabel: str | None = None, title: str | None = None, floor: float = 1e-300, logx: bool = False):
    """Convergence histories from ``Solution.history``, one line per run, on a log scale.

    ``runs`` are ``(label, Solution)`` or ``(label, Solution, style)`` with ``style`` a dict of
    matplotlib line properties. ``key`` names the history entry to draw (e.g. ``"dual_change"``
    of the Uzawa solver), or is a sequence of names: then each run draws the first one its
    history has, and the legend says which. Runs with none of them are listed as skipped in
    the legend title; InputError if no run has any. ``logx`` puts the iterations on a log scale
    (useful when one run takes hundreds of iterations and the others a few)."""
    ax = _axes(ax, lines=True)
    keys = (key,) if isinstance(key, str) else tuple(key)
    n = 0
    skipped = []
    for item in runs:
        label, sol = item[0], item[1]
        style = dict(item[2]) if len(item) > 2 and item[2] else {}
        found = next(((k, ser) for k in keys if (ser := history_series(sol, k)) is not None), None)
        if found is None:
            skipped.append(label)
            continue
        k, (it, val) = found
        what = f"{k}, " if len(keys) > 1 else ""
        status = getattr(sol, "status", None)
        style.setdefault("marker", "." if len(it) < 60 else None)
        style.setdefault("ms", 3)
        style.setdefault("lw", 1)
        ax.plot(it, np.maximum(np.abs(val), floor),
                label=f"{label} ({what}{len(it)} records{', ' + str(status) if status is not None else ''})", **style)
        n += 1
    if n == 0:
        raise InputError(f"no run has a history with {' or '.join(map(repr, keys))}")
    ax.set_yscale("log")
    if logx:
        ax.set_xscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel(ylabel or " / ".join(keys))
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, title=("no history: " + ", ".join(skipped)) if skipped else None, title_fontsize=7)
    if title:
        ax.set_title(title, fontsize=10)
    return ax
