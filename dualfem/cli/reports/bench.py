"""``dualfem report bench RESULTS...``: reports/benchmark.md + PNGs from ``dualfem bench`` results.

Reads the results and writes the report with :func:`dualfem.reports.bench.build_report`.
"""
from __future__ import annotations

import shlex
import sys
from pathlib import Path

from dualfem.cli.options import OneLineParser
from dualfem.cli.report import register_report
from dualfem.cli.reports._args import add_target_args, target_args


@register_report("bench", "benchmark report (work-precision, scaling, tiers) from a 'dualfem bench' results.csv")
def run(argv: list[str]) -> int:
    from dualfem.reports.bench import build_report

    p = OneLineParser(prog="dualfem report bench",
                                description="reports/benchmark.md + PNGs from a dualfem bench results.csv")
    p.add_argument("results", metavar="RESULTS", nargs="+",
                   help="results.csv or a sweep's output directory; several are merged, a later one replacing "
                        "the rows of an earlier one that measure the same thing")
    p.add_argument("--md", default="dualfem-results/reports/benchmark.md",
                   help="markdown output (default dualfem-results/reports/benchmark.md; reports/benchmark.md for the "
                        "committed one)")
    p.add_argument("--figdir", default=None, help="figure directory (default: bench/ beside --md)")
    add_target_args(p)
    try:
        a = p.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    from dualfem.experiments.store import check_report_input

    for item in a.results:
        check_report_input(item)       # one line for what the report cannot read (experiments/store.py)
    targets = target_args(a)
    cmd = "dualfem report bench " + " ".join(shlex.quote(x) for x in argv)
    figdir = a.figdir or str(Path(a.md).parent / "bench")
    md = build_report(a.results, a.md, figdir, command=cmd, **targets)
    n = len(list(Path(figdir).glob("*.png")))
    print(f"wrote {md} and {n} figure{'s' if n != 1 else ''} in {figdir}", file=sys.stderr)
    return 0
