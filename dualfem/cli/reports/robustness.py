"""``dualfem report robustness --out DIR``: the bad-input corpus, refused or answered, case by case.

Runs the corpus (:func:`dualfem.experiments.robustness.run_corpus`, ``tests/bad_inputs`` of a
checkout) through this command line's own entry point, then writes ``DIR/robustness.md`` with
:func:`dualfem.reports.robustness.render`.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

from dualfem.cli.options import OneLineParser
from dualfem.cli.report import register_report
from dualfem.core.errors import InputError

#: the corpus of a source checkout (it ships with the tests, not with the package)
CORPUS = Path(__file__).resolve().parents[3] / "tests" / "bad_inputs"


@register_report("robustness", "the bad-input corpus: refused cleanly / answered / tracebacks / data lost")
def report_robustness(argv: list[str]) -> int:
    from dualfem.cli.main import main
    from dualfem.core.io import atomic_write_text, check_output_path
    from dualfem.experiments.machine import machine_info
    from dualfem.experiments.robustness import run_corpus
    from dualfem.reports.robustness import render

    ap = OneLineParser(prog="dualfem report robustness")
    ap.add_argument("--out", required=True, metavar="DIR",
                    help="folder for robustness.md (reports/ for the committed one)")
    ap.add_argument("--corpus", default=str(CORPUS), metavar="DIR", help="the corpus folder (default tests/bad_inputs)")
    args = ap.parse_args(argv)
    corpus = Path(args.corpus)
    if not (corpus / "cases.toml").is_file():
        raise InputError(f"--corpus {str(corpus)!r} has no cases.toml (the corpus ships with a source checkout)")
    md = check_output_path(Path(args.out) / "robustness.md", "--out")
    t0 = time.perf_counter()
    recs = run_corpus(corpus, main, progress=lambda s: print(s, file=sys.stderr, flush=True))
    m = machine_info()
    machine = f"{m['cpu']}, {m['cores']} cores, Python {m['python']}, commit {m['git'] or '?'}, " \
              f"{time.perf_counter() - t0:.0f} s"
    atomic_write_text(md, render(recs, "dualfem report robustness " + " ".join(argv), machine))
    print(f"wrote {md}", file=sys.stderr)
    return 0
