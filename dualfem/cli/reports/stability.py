"""``dualfem report stability RESULTS [OUTPUT.md]``: reports/stability.md from a ``dualfem stress`` run.

Reads the results (:func:`dualfem.experiments.stress.load_results`) and writes the Markdown and
its figures with :func:`dualfem.reports.stability.render` (figures in ``<its folder>/stability/``).
"""
from __future__ import annotations

from pathlib import Path

from dualfem.cli.options import OneLineParser
from dualfem.cli.report import register_report
from dualfem.core.errors import InputError


@register_report("stability", "numerical-stability grid: colour maps and silent wrong answers (from dualfem stress)")
def run(argv: list[str]) -> int:
    from dualfem.core.io import atomic_write_text
    from dualfem.experiments.stress import load_results
    from dualfem.reports.stability import render

    ap = OneLineParser(prog="dualfem report stability",
                                 description="write reports/stability.md from a dualfem stress results directory")
    ap.add_argument("results", metavar="RESULTS", help="directory written by dualfem stress (runs.jsonl, meta.json)")
    ap.add_argument("output", nargs="?", default=None, metavar="OUTPUT.md",
                    help="Markdown file to write (default reports/stability.md; figures go to <its folder>/stability/)")
    ap.add_argument("-o", "--output", dest="output_opt", default=None, metavar="FILE",
                    help="same as OUTPUT.md (needs 'dualfem report stability -- RESULTS -o FILE')")
    try:
        args = ap.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    out = Path(args.output_opt or args.output or "dualfem-results/reports/stability.md")
    if out.suffix != ".md":
        raise InputError(f"OUTPUT must name a .md file, got {str(out)!r}")
    meta, recs = load_results(args.results)
    if not recs:
        raise InputError(f"RESULTS {args.results!r} holds no runs")
    text = render(meta, recs, out)
    atomic_write_text(out, text)
    print(f"wrote {out} and {out.parent / 'stability'}/*.png ({len(recs)} runs)")
    return 0
