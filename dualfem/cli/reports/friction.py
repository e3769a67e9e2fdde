"""``dualfem report friction``: friction against closed forms (reports/friction.md).

Runs :func:`dualfem.experiments.friction.study`, stores its numbers in ``OUT/friction.json`` and renders with
:func:`dualfem.reports.friction.render`; ``--from-json FILE`` reads numbers stored earlier instead (no solves);
``--quick`` is one coarse level of each (for a try: minutes less).
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from dualfem.cli.options import OneLineParser
from dualfem.cli.report import register_report
from dualfem.cli.reports._args import strip_dashes
from dualfem.core.errors import InputError


@register_report("friction", "friction on the defects against closed forms: 2D inclined crack, 3D penny, a stuck "
                             "crack, solvers compared (~15 min; --quick ~1 min; --from-json re-renders)")
def run(argv: list[str]) -> int:
    from dualfem.core.io import atomic_write_text, check_input_path, dumps
    from dualfem.reports.friction import check_study, render

    ap = OneLineParser(prog="dualfem report friction", description="render the friction study (reports/friction.md)")
    ap.add_argument("--out", default="dualfem-results/reports",
                    help="output directory (default dualfem-results/reports; reports/ for the committed one)")
    ap.add_argument("--solver", default="clarabel", help="the solver of the validation cases (default clarabel)")
    ap.add_argument("--compare", default="", metavar="S1,S2",
                    help="comma-separated solvers to run on four frictional scenes (default: none)")
    ap.add_argument("--quick", action="store_true", help="one coarse level of each case")
    ap.add_argument("--resume", action="store_true",
                    help="keep the rows of OUT/friction.json of the same case, level and solver (not skipped ones)")
    ap.add_argument("--coulomb-levels", type=int, default=2,
                    help="2D Coulomb cases on this many of the coarsest levels (default 2: each is a fixed point of "
                         "several solves)")
    ap.add_argument("--from-json", default=None, metavar="FILE",
                    help="re-render from a friction.json (no solves; with --compare: run the solvers' comparison "
                         "on its scenes and store it)")
    argv = strip_dashes(argv)
    args = ap.parse_args(argv)
    out = Path(args.out)
    if args.from_json:
        check_input_path(args.from_json, "--from-json")
        try:
            res = json.loads(Path(args.from_json).read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise InputError(f"--from-json {args.from_json!r}: cannot read it: {exc}") from None
        check_study(res, f"--from-json {args.from_json!r}")
        solvers = [s.strip() for s in args.compare.split(",") if s.strip()]
        if solvers:                 # the solvers' comparison alone, on the stored study's scenes
            from dualfem.experiments.friction import compare

            res["compare"] = compare(res, solvers, lambda m: print(m, file=sys.stderr, flush=True))
            base = str(res.get("command", "dualfem report friction")).split("; then ")[0]   # the study's own run
            res["command"] = f"{base}; then dualfem report friction {' '.join(argv)}"
            out.mkdir(parents=True, exist_ok=True)
            atomic_write_text(out / "friction.json", dumps(res) + "\n")
        md = render(res, out, res.get("command"))
        print(f"wrote {md} from {args.from_json}", file=sys.stderr)
        return 0
    from dualfem.experiments import friction as fr

    solvers = [s.strip() for s in args.compare.split(",") if s.strip()]
    kw = {"levels_2d": fr.LEVELS_2D[:1], "angles": (20.0, 30.0), "levels_3d": ((3.0, 0.5),)} if args.quick else {}
    resume = None
    if args.resume and (out / "friction.json").is_file():
        resume = json.loads((out / "friction.json").read_text(encoding="utf-8"))
        check_study(resume, f"--resume {str(out / 'friction.json')!r}")
    t0 = time.perf_counter()
    res = fr.study(solver=args.solver, solvers=solvers, progress=lambda m: print(m, file=sys.stderr, flush=True),
                   coulomb_levels=args.coulomb_levels, resume=resume, **kw)
    res["time_s"] = time.perf_counter() - t0
    res["command"] = " ".join(["dualfem report friction", *argv])
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "friction.json", dumps(res) + "\n")
    md = render(res, out, res["command"])
    print(f"wrote {md}", file=sys.stderr)
    return 0
