"""``dualfem report html RESULTS... --out DIR``: a self-contained interactive dashboard (DIR/index.html).

Reads bench (or stress) results folders and writes the page with
:func:`dualfem.reports.html.build_dashboard` (plotly.js embedded: no network needed to open it).
"""
from __future__ import annotations

import shlex
import sys

from dualfem.cli.options import OneLineParser
from dualfem.cli.report import register_report
from dualfem.cli.reports._args import add_target_args, strip_dashes, target_args


@register_report("html", "interactive dashboard (DIR/index.html, self-contained): work-precision curves, rankings, "
                         "success and correct rates, selectable by scene, delta, tier and solver")
def run(argv: list[str]) -> int:
    from dualfem.reports.html import build_dashboard

    p = OneLineParser(prog="dualfem report html",
                                description="a self-contained interactive dashboard (DIR/index.html) from "
                                            "'dualfem bench' (or 'dualfem stress') results folders")
    p.add_argument("results", metavar="RESULTS", nargs="+",
                   help="results folders (or their results.csv); several are merged, a later one replacing the rows "
                        "of an earlier one that measure the same thing")
    p.add_argument("--out", default="dualfem-results/reports/dashboard", metavar="DIR",
                   help="folder of index.html (default dualfem-results/reports/dashboard); a folder holding other "
                        "files is refused without --force")
    p.add_argument("--force", action="store_true",
                   help="write index.html into a DIR that holds other files, or replace an index.html this command "
                        "did not write (nothing else in DIR is touched)")
    add_target_args(p)
    try:
        a = p.parse_args(strip_dashes(argv))
    except SystemExit as exc:
        return int(exc.code or 0)
    targets = target_args(a)
    cmd = "dualfem report html " + " ".join(shlex.quote(x) for x in argv)
    index = build_dashboard(a.results, a.out, force=a.force, command=cmd, **targets)
    print(f"wrote {index} (open it in a browser; no network needed)", file=sys.stderr)
    return 0
