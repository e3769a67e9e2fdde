"""``dualfem bench SPEC.toml [-s SOLVER[K=V,...]] [-d SCENE[K=V,...]] [-r REPEATS] [--jobs N] [--dask ADDRESS]
[--out DIR] [--resume] [--force]``: run or resume a sweep (the spec format and the options: docs/bench.md).

The one sweep engine (:func:`dualfem.experiments.bench.run_tasks`, shared with ``dualfem stress``):
``--jobs`` parallel guarded workers, ``--resume`` continues DIR (finished rows kept and not
redone; for bench also what a plain rerun does), ``--force`` writes into a DIR that holds the
results of another spec (nothing in it is dropped).
"""
from __future__ import annotations

import os
import shlex
import sys
from pathlib import Path

from dualfem.cli.main import add_factor_arg, add_tol_arg, apply_factor, command, max_threads
from dualfem.cli.options import add_solver_option, float_in, int_in
from dualfem.core.errors import InputError
from dualfem.experiments.spec import MAX_REPEATS


def _cfg(p):
    add_factor_arg(p)
    p.add_argument("spec", metavar="SPEC.toml", help="sweep spec (see benchmarks/default.toml)")
    add_solver_option(p, "run only this solver's blocks of the spec (added when the spec has none), with these "
                         "parameters (a list KEY=[a,b] is a grid); repeatable. See docs/bench.md")
    p.add_argument("-d", "--scene", action="append", metavar="SCENE[KEY=V,...]", default=None,
                   help="run only this scene of the spec's [[scenes]] blocks (added when it has none), with these "
                        "scene keys (a list is a grid dimension); repeatable")
    p.add_argument("-r", "--repeats", type=int_in(1, MAX_REPEATS), metavar="REPEATS", default=None,
                   help="timed repeats of every run and of the floor (overrides the spec)")
    add_tol_arg(p)
    p.add_argument("--jobs", type=int_in(1, max_threads()), default=1, metavar="N",
                   help="parallel worker processes (joblib/loky); default 1 (timings are cleanest serially)")
    p.add_argument("--dask", metavar="ADDRESS", default=None,
                   help="send the tasks to this dask.distributed scheduler (e.g. tcp://10.0.0.1:8786)")
    p.add_argument("--dask-timeout", metavar="SECONDS", type=float_in(0, 86400), default=20.0,
                   help="seconds to wait for the --dask scheduler before refusing its address (default 20)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="results directory (default dualfem-results/bench/<spec name>, or "
                        "<spec name>-<8 hex digits of the selection> with -s/-d/-r); rerun to resume")
    p.add_argument("--resume", action="store_true",
                   help="continue --out: finished rows are kept and not redone (a rerun without it does the same)")
    p.add_argument("--force", action="store_true",
                   help="write into an --out that holds the results of another spec (its rows are kept)")
    p.add_argument("--retry-failed", action="store_true",
                   help="also redo finished runs whose status is not solved/inaccurate")
    p.add_argument("--no-progress-bar", action="store_true",
                   help="plain progress lines even on a terminal")


def default_name(spec_name: str, options: tuple[str, ...]) -> str:
    """The default results folder's name: the spec's name, and with a selection (``-s``/``-d``/``-r``)
    the first 8 hex digits of its SHA-256 (so two selections of one spec never share a folder)."""
    if not options:
        return spec_name
    import hashlib

    return f"{spec_name}-{hashlib.sha256(' '.join(options).encode()).hexdigest()[:8]}"


@command("bench", "run (or resume) a benchmark sweep: every solver, error against time")(_cfg)
def cmd_bench(args) -> int:
    apply_factor(args)
    from dualfem.experiments.bench import run_sweep
    from dualfem.experiments.spec import load_spec
    from dualfem.experiments.spec_select import make_selection
    from dualfem.experiments.store import default_out

    max_jobs = 4 * (os.cpu_count() or 1)
    if not 1 <= args.jobs <= max_jobs:
        raise InputError(f"--jobs must be an integer in 1..{max_jobs} (4 x the {os.cpu_count()} cores), "
                         f"got {args.jobs}")
    if args.dask is not None and args.jobs != 1:
        raise InputError("--jobs and --dask exclude each other: the dask scheduler decides the parallelism")
    from dualfem.core.errors import check_positive

    dask_timeout = check_positive("--dask-timeout", args.dask_timeout)    # also when called from Python
    from dualfem.experiments.tolerance import check_tol

    tol = check_tol(args.tol)
    opts = tuple(f"{flag} {shlex.quote(v)}" for flag, vals in (("-s", args.solver), ("-d", args.scene))
                 for v in vals or ()) + ((f"-r {args.repeats}",) if args.repeats is not None else ()) \
        + ((f"--tol {tol:g}",) if tol is not None else ())
    selection = make_selection(args.solver, args.scene, args.repeats, opts, tol)
    spec = load_spec(args.spec, selection)
    out = Path(args.out) if args.out else default_out("bench", default_name(spec.name, opts))
    if sys.argv[1:2] == ["bench"]:
        command = "dualfem bench " + " ".join(shlex.quote(a) for a in sys.argv[2:])
    else:   # called through main(argv) from Python: rebuild it from the parsed arguments
        command = f"dualfem bench {shlex.quote(args.spec)} --jobs {args.jobs}" + \
            (f" --dask {shlex.quote(args.dask)}" if args.dask else "") + "".join(f" {o}" for o in opts) + \
            (f" --out {shlex.quote(str(out))}")
    summary = run_sweep(spec, out, jobs=args.jobs, dask=args.dask, command=command,
                        progress=not args.no_progress_bar, retry_failed=args.retry_failed, force=args.force,
                        connect_timeout=dask_timeout)
    st = ", ".join(f"{k} {v}" for k, v in sorted(summary.statuses.items())) or "nothing to do"
    print(f"{summary.out}/results.csv: {summary.total} runs in the spec, {summary.skipped_done} already done, "
          f"{summary.ran} executed now ({st}); {summary.aux} reference/floor tasks", file=sys.stderr)
    print(f"report: dualfem report bench {summary.out}/results.csv", file=sys.stderr)
    return 0
