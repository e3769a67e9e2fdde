"""``dualfem report figures``: the paper's figures and the scene library's (reports/figures.md + figures/*.png).

Runs :func:`dualfem.experiments.figures.collect` (every solve), then draws and writes with
:func:`dualfem.reports.figures.render` (which only looks the study's solutions up).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from dualfem.cli.options import OneLineParser
from dualfem.cli.report import register_report
from dualfem.cli.reports._args import strip_dashes
from dualfem.core.errors import InputError
from dualfem.experiments.figures import SWEEP


def generate(outdir: Path, N: int = 64, solver: str | None = None, scale: float = 300.0, dpi: int = 110,
             sweep=SWEEP, history_solvers: list[str] | None = None, progress=print, scenes: bool = True,
             scene_overrides: dict | None = None) -> str:
    """Run the study, then render (the text of figures.md); ``scenes``: the scene library too."""
    from dualfem.experiments.figures import collect
    from dualfem.reports.figures import render

    data = collect(N=N, solver=solver, sweep=sweep, history_solvers=history_solvers, progress=progress,
                   scenes=scenes, scene_overrides=scene_overrides)
    return render(data, outdir, scale=scale, dpi=dpi)


@register_report("figures", "the paper's figures (deformed bodies, jumps, faces, pressure, Uzawa histories) "
                            "and the scene library's deformed bodies with every defect")
def run(argv: list[str]) -> int:
    ap = OneLineParser(prog="dualfem report figures", description=__doc__.splitlines()[0])
    ap.add_argument("--N", type=int, default=64, help="mesh size N (default 64)")
    ap.add_argument("--solver", default=None,
                    help="solver for the pictures (default: the reference policy's first, Solver.reference)")
    ap.add_argument("--scale", type=float, default=300.0, help="displacement magnification (default 300, as the paper)")
    ap.add_argument("--dpi", type=int, default=110)
    ap.add_argument("--history-solvers", default=None, metavar="A,B",
                    help="solvers besides the paper's method whose histories are drawn (default: every registered "
                         "one that records a history, found by a solve of a tiny scene)")
    ap.add_argument("--scenes", action=argparse.BooleanOptionalAction, default=True,
                    help="include the scene library (scenes/*.toml) section (default: yes)")
    ap.add_argument("--out", default="dualfem-results/reports",
                    help="output directory (default dualfem-results/reports; reports/ for the committed one)")
    argv = strip_dashes(argv)
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
                    progress=lambda m: print(m, file=sys.stderr, flush=True), scenes=args.scenes)
    from dualfem.core.io import atomic_write_text

    atomic_write_text(out / "figures.md", text + f"\n_Wall time {time.perf_counter() - t0:.0f} s._\n")
    print(f"wrote {out / 'figures.md'}", file=sys.stderr)
    return 0
