"""``dualfem report html RESULTS... --out DIR``: a self-contained interactive dashboard (DIR/index.html).

Reads bench (or stress) results folders and writes the page with
:func:`dualfem.reports.html.build_dashboard` (plotly.js embedded: no network needed to open it).
"""
from __future__ import annotations

import argparse
import math
import shlex
import sys

from dualfem.cli.report import register_report
from dualfem.cli.reports._args import strip_dashes
from dualfem.core.errors import InputError
from dualfem.reports._bench_util import OURS


@register_report("html", "interactive dashboard (DIR/index.html, self-contained): work-precision curves, rankings, "
                         "success and correct rates, selectable by scene, delta, tier and solver")
def run(argv: list[str]) -> int:
    from dualfem.reports.html import build_dashboard

    p = argparse.ArgumentParser(prog="dualfem report html",
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
    p.add_argument("--ours", default=",".join(OURS), help="comma-separated solvers checked against the targets")
    p.add_argument("--shift", type=float, default=10.0, help="shift of the geometric mean in seconds (10)")
    p.add_argument("--error", type=float, default=1e-8, help="equal-error level of the targets (1e-8)")
    try:
        a = p.parse_args(strip_dashes(argv))
    except SystemExit as exc:
        return int(exc.code or 0)
    if not (a.shift >= 0 and math.isfinite(a.shift)):
        raise InputError(f"--shift must be a finite number >= 0, got {a.shift}")
    if not (a.error > 0 and math.isfinite(a.error)):
        raise InputError(f"--error must be a finite number > 0, got {a.error}")
    cmd = "dualfem report html " + " ".join(shlex.quote(x) for x in argv)
    index = build_dashboard(a.results, a.out, force=a.force, shift=a.shift,
                            ours=[s for s in a.ours.split(",") if s], err_target=a.error, command=cmd)
    print(f"wrote {index} (open it in a browser; no network needed)", file=sys.stderr)
    return 0
