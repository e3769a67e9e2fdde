"""``dualfem report convergence``: the mesh-convergence study (reports/convergence.md).

Runs :func:`dualfem.experiments.convergence.study`, stores its numbers in ``OUT/convergence.json``
and renders with :func:`dualfem.reports.convergence.render`; ``--from-json FILE`` reads numbers
stored earlier instead (no solves).
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from dualfem.cli.options import OneLineParser
from dualfem.cli.report import register_report
from dualfem.cli.reports._args import floats, ints, strip_dashes
from dualfem.core.errors import InputError
from dualfem.core.scene import DEFAULT_SCENE
from dualfem.experiments.convergence import DEFAULT_DELTAS, DEFAULT_NS, DEFAULT_REF


def _read_json(path: str, flag: str) -> dict:
    """A stored study (``convergence.json``), checked by :func:`dualfem.reports.convergence.check_study`
    before anything is drawn; a FIFO or a device is refused before it is opened."""
    from dualfem.core.io import check_input_path
    from dualfem.reports.convergence import check_study

    check_input_path(path, flag)
    try:
        res = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"{flag} {path!r}: cannot read it: {exc}") from None
    check_study(res, f"{flag} {path!r}")
    return res


@register_report("convergence", f"mesh-convergence study of {DEFAULT_SCENE} against a fine reference (slow: ~8 min "
                                "per delta at the defaults, ~9 GB; --from-json re-renders)")
def run(argv: list[str]) -> int:
    from dualfem.core.io import atomic_write_text, dumps
    from dualfem.reports.convergence import render

    ap = OneLineParser(prog="dualfem report convergence",
                                 description="render the mesh-convergence study (reports/convergence.md)")
    ap.add_argument("--deltas", default=",".join(f"{d:g}" for d in DEFAULT_DELTAS), help="comma-separated deltas")
    ap.add_argument("--N", dest="Ns", default=",".join(map(str, DEFAULT_NS)), help="comma-separated coarse N")
    ap.add_argument("--ref-N", type=int, default=DEFAULT_REF,
                    help=f"N of the fine reference mesh (default {DEFAULT_REF})")
    ap.add_argument("--solver", default=None,
                    help="exact solver (default: the reference policy's first installed candidate, Solver.reference)")
    ap.add_argument("--scene", default=DEFAULT_SCENE)
    ap.add_argument("--out", default="dualfem-results/reports",
                    help="output directory (default dualfem-results/reports; reports/ for the committed one)")
    ap.add_argument("--from-json", default=None, metavar="FILE",
                    help="re-render the report and plots from a convergence.json written earlier (no solves)")
    ap.add_argument("--supplement", action="append", default=[], metavar="FILE",
                    help="append the results of another run (its convergence.json), e.g. a finer reference "
                         "for one delta")
    argv = strip_dashes(argv)
    args = ap.parse_args(argv)
    supplements = [_read_json(f, "--supplement") for f in args.supplement]
    out = Path(args.out)
    if args.from_json:
        res = _read_json(args.from_json, "--from-json")
        res["supplements"] = supplements or res.get("supplements", [])
        atomic_write_text(out / "convergence.json", dumps(res) + "\n")
        md = render(res, out, res.get("command", "dualfem report convergence"))
        print(f"wrote {md} from {args.from_json}", file=sys.stderr)
        return 0
    from dualfem.experiments.convergence import exact_solver, study

    deltas = floats(args.deltas, "--deltas")
    Ns = sorted(ints(args.Ns, "--N"))
    if any(args.ref_N % n or args.ref_N <= n for n in Ns):
        raise InputError(f"--ref-N ({args.ref_N}) must be a multiple of, and larger than, every coarse N ({Ns})")
    solver = exact_solver(args.solver)
    t0 = time.perf_counter()
    res = study(deltas, Ns, args.ref_N, solver, args.scene, progress=lambda m: print(m, file=sys.stderr, flush=True))
    res["time_s"] = time.perf_counter() - t0
    res["supplements"] = supplements
    res["command"] = " ".join(["dualfem report convergence", *argv])
    atomic_write_text(out / "convergence.json", dumps(res) + "\n")
    md = render(res, out, res["command"])
    print(f"wrote {md}", file=sys.stderr)
    return 0
