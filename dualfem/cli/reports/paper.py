"""``dualfem report paper``: the paper's Tables 1-3 beside our k / m (reports/paper_tables.md).

Runs :func:`dualfem.experiments.paper.collect`, stores its data in the ``--data`` JSON (default:
the ``--out`` path with ``.json``), then renders with :func:`dualfem.reports.paper.render`;
``--render-only`` reads the stored data and runs nothing.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from dualfem.cli.main import OneLineParser
from dualfem.cli.report import register_report
from dualfem.core.errors import InputError


def _ints(text: str) -> list[int]:
    try:
        vals = [int(n) for n in text.split(",") if n.strip()]
    except ValueError:
        raise InputError(f"--N must be comma-separated integers >= 4, got {text!r}") from None
    if not vals or min(vals) < 4:
        raise InputError(f"--N must be comma-separated integers >= 4, got {text!r}")
    return vals


@register_report("paper", "the paper's Tables 1-3 beside our k / m (reports/paper_tables.md)")
def report_paper(argv: list[str]) -> int:
    from dualfem.core.io import atomic_write_text
    from dualfem.reports.paper import render

    ap = OneLineParser(prog="dualfem report paper")
    ap.add_argument("--N", default="16,32,64,128,256", help="comma-separated mesh sizes")
    ap.add_argument("--inner-N", default=None, help="mesh sizes of the inner stop test study (default: N <= 128)")
    ap.add_argument("--out", default="dualfem-results/reports/paper_tables.md",
                    help="output (default dualfem-results/reports/paper_tables.md; reports/paper_tables.md for the "
                         "committed one)")
    ap.add_argument("--data", default=None, help="data JSON (default: the --out path with .json)")
    ap.add_argument("--render-only", action="store_true", help="re-render from the data JSON, run nothing")
    args = ap.parse_args(argv)
    data_path = Path(args.data) if args.data else Path(args.out).with_suffix(".json")
    if args.render_only:
        data = json.loads(data_path.read_text())
        command = data.get("command", "dualfem report paper")
    else:
        from dualfem.experiments.paper import collect

        tty = sys.stderr.isatty()

        def progress(msg):
            print(msg, file=sys.stderr, end="\r" if tty else "\n", flush=True)

        data = collect(_ints(args.N), ["strain", "stress"], _ints(args.inner_N) if args.inner_N else None,
                       progress=progress)
        data["command"] = "dualfem report paper" + (" " + " ".join(argv) if argv else "")
        atomic_write_text(data_path, json.dumps(data, indent=1) + "\n")
        command = data["command"]
    atomic_write_text(args.out, render(data, command))
    print(f"wrote {args.out}" + ("" if args.render_only else f" and {data_path}"), file=sys.stderr)
    return 0
