"""``dualfem report plugins``: the Signorini problem plugin and the template solver (reports/plugins.md).

Runs :func:`dualfem.experiments.plugins.collect`, then draws and writes with
:func:`dualfem.reports.plugins.render`.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

from dualfem.cli.options import OneLineParser
from dualfem.cli.report import register_report
from dualfem.core.errors import InputError, check_int
from dualfem.core.scene import DEFAULT_SCENE


def generate(out: Path, N: int = 32, dpi: int = 110, sizes=(16, 32, 64, 128)) -> str:
    """Run the study, then render (the text of plugins.md)."""
    from dualfem.experiments.plugins import collect
    from dualfem.reports.plugins import render

    return render(collect(N=N, sizes=sizes), out, dpi)


@register_report("plugins", "Signorini problem plugin and template solver: every solver, physics checks, figure")
def run(argv: list[str]) -> int:
    ap = OneLineParser(prog="dualfem report plugins", description=__doc__.splitlines()[0])
    ap.add_argument("--N", type=int, default=32, help="mesh size of the Signorini scene (default 32)")
    ap.add_argument("--dpi", type=int, default=110)
    ap.add_argument("--sizes", default="16,32,64,128", metavar="N,N,...",
                    help=f"mesh sizes of the template solver's cost table (scene {DEFAULT_SCENE}; "
                         "default 16,32,64,128)")
    ap.add_argument("--out", default="dualfem-results/reports",
                    help="output directory (default dualfem-results/reports; reports/ for the committed one)")
    args = ap.parse_args(argv)
    try:
        sizes = [int(v) for v in args.sizes.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"--sizes must be comma-separated multiples of 4, got {args.sizes!r}") from None
    for v in sizes:
        check_int("--sizes", v, 4, 1024)
        if v % 4:
            raise InputError(f"--sizes must be multiples of 4 (the {DEFAULT_SCENE} defect ends at 1/4, 3/4), got {v}")
    N = check_int("--N", args.N, 4, 512)
    dpi = check_int("--dpi", args.dpi, 30, 600)
    out = Path(args.out)
    t0 = time.perf_counter()
    text = generate(out, N=N, dpi=dpi, sizes=sizes)
    from dualfem.core.io import atomic_write_text

    atomic_write_text(out / "plugins.md", text + f"\n_Wall time {time.perf_counter() - t0:.0f} s._\n")
    print(f"wrote {out / 'plugins.md'}", file=sys.stderr)
    return 0
