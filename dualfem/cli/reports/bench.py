"""``dualfem report bench RESULTS...``: reports/benchmark.md + PNGs from ``dualfem bench`` results.

Reads the results and writes the report with :func:`dualfem.reports.bench.build_report`.
"""
from __future__ import annotations

import argparse
import math
import shlex
import sys
from pathlib import Path

from dualfem.cli.report import register_report
from dualfem.core.errors import InputError
from dualfem.reports._bench_util import OURS


@register_report("bench", "benchmark report (work-precision, scaling, tiers) from a 'dualfem bench' results.csv")
def run(argv: list[str]) -> int:
    from dualfem.reports.bench import build_report

    p = argparse.ArgumentParser(prog="dualfem report bench",
                                description="reports/benchmark.md + PNGs from a dualfem bench results.csv")
    p.add_argument("results", metavar="RESULTS", nargs="+",
                   help="results.csv or a sweep's output directory; several are merged, a later one replacing "
                        "the rows of an earlier one that measure the same thing")
    p.add_argument("--md", default="dualfem-results/reports/benchmark.md",
                   help="markdown output (default dualfem-results/reports/benchmark.md; reports/benchmark.md for the "
                        "committed one)")
    p.add_argument("--figdir", default=None, help="figure directory (default: bench/ beside --md)")
    p.add_argument("--ours", default=",".join(OURS),
                   help="comma-separated solvers checked against the targets")
    p.add_argument("--shift", type=float, default=10.0, help="shift of the geometric mean in seconds (10)")
    p.add_argument("--error", type=float, default=1e-8, help="equal-error level of the targets (1e-8)")
    try:
        a = p.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    if not (a.shift >= 0 and math.isfinite(a.shift)):
        raise InputError(f"--shift must be a finite number >= 0, got {a.shift}")
    if not (a.error > 0 and math.isfinite(a.error)):
        raise InputError(f"--error must be a finite number > 0, got {a.error}")
    cmd = "dualfem report bench " + " ".join(shlex.quote(x) for x in argv)
    figdir = a.figdir or str(Path(a.md).parent / "bench")
    md = build_report(a.results, a.md, figdir, ours=[s for s in a.ours.split(",") if s], shift=a.shift,
                      err_target=a.error, command=cmd)
    print(f"wrote {md} and figures in {figdir}", file=sys.stderr)
    return 0
