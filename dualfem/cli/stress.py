"""``dualfem stress [--quick] [--axes ...] [--solvers ...] [--scene ...] [--out DIR] [--jobs N] [--resume] [--force]``.

The numerical-stability grid (:mod:`dualfem.experiments.stress`), run by the one sweep engine of
``dualfem bench`` into its results store (``results.csv``, ``rows/``; plus ``meta.json``).
``--jobs``, ``--resume`` and ``--force`` mean what they mean for ``dualfem bench``.
"""
from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

from dualfem.cli.main import add_factor_arg, apply_factor, command
from dualfem.core.errors import InputError, describe_exception
from dualfem.core.io import RESULTS_ENTRIES, check_folder_files


def _cfg(p):
    add_factor_arg(p)
    p.add_argument("--quick", action="store_true",
                   help="small version: N=16 base scene, load f2 only on the delta axis, N up to 128, "
                        "20 s per-run time limit (default: N=32, loads f1/f2/f3, N up to 1024, 120 s)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="results directory (results.csv, rows/, meta.json; a folder of runs.jsonl written by an "
                        "earlier version is read and, with --resume, continued); default dualfem-results/stress/quick "
                        "or .../full, with --scene .../quick-SCENE or .../full-SCENE (the committed grid is "
                        "regenerated only with an explicit --out benchmarks/results/stress)")
    p.add_argument("--scene", default=None, metavar="SCENE",
                   help="base scene of any registered problem: a scene of the library (e.g. two_defects), a preset "
                        "(e.g. signorini) or a .toml file (default: the paper's f2, N = 32, or 16 with --quick); it "
                        "keeps its own mesh and load except on the N axis; only the axes that apply to its problem "
                        "are run")
    p.add_argument("--solvers", default=None, metavar="A,B",
                   help="comma-separated solver names, or 'all' (the default): every registered solver; one that "
                        "is not installed gives skipped runs with its install hint")
    p.add_argument("--axes", default=None, metavar="A,B",
                   help="which axes: delta, r, units, load, nu, N (default all that apply to the scene)")
    p.add_argument("--time-limit", type=str, default=None, metavar="SECONDS",
                   help="per-run solver time limit (passed to solvers that take one; the harness kills "
                        "a run after 2x this plus an assembly allowance)")
    p.add_argument("--max-n", type=str, default=None, metavar="N", help="largest N on the N axis")
    p.add_argument("-j", "--jobs", type=str, default="1", metavar="J",
                   help="parallel guarded worker processes (joblib; default 1)")
    p.add_argument("--resume", action="store_true",
                   help="continue DIR: every finished row is kept and not redone, the rest run; rows of other "
                        "runs in DIR are always kept")
    p.add_argument("--force", action="store_true",
                   help="write into a DIR that holds the results of another spec (e.g. a bench sweep), adding "
                        "this grid's rows to it (nothing is dropped)")
    p.add_argument("--retry-failed", action="store_true",
                   help="with --resume: also redo finished runs whose status is not solved/inaccurate")
    p.add_argument("--dry-run", action="store_true",
                   help="print the number of runs per axis and the time estimate (one timed run of the base "
                        "scene, as every grid prints before it starts), then exit")


@command("stress", "run the numerical-stability grid (delta, r, units, load, nu, N) over every solver")(_cfg)
def cmd_stress(args) -> int:
    apply_factor(args)
    from dualfem.core.errors import check_int, check_positive
    from dualfem.core.registry import solvers
    from dualfem.experiments import reference, stress
    from dualfem.experiments.store import default_out

    reg = solvers()
    names = _choice("--solvers", args.solvers, sorted(reg), "solver", "known solvers")
    axes = None if args.axes is None or args.axes.strip() == "all" else \
        tuple(_choice("--axes", args.axes, list(stress.AXES), "axis", "allowed"))
    tl = None if args.time_limit is None else check_positive("--time-limit", args.time_limit)
    max_n = None if args.max_n is None else check_int("--max-n", args.max_n, 8, 4096)
    jobs = check_int("--jobs", args.jobs, 1, 4 * (os.cpu_count() or 1))
    grid = ("quick" if args.quick else "full") + ("-" + "".join(c if c.isalnum() or c in "_-" else "_" for c in
                                                          Path(args.scene).stem)[:40] if args.scene else "")
    out = Path(args.out) if args.out else default_out("stress", grid)     # one folder per grid and scene
    if out.exists() and not out.is_dir():
        raise InputError(f"--out must be a directory, {str(out)!r} is a file")
    check_folder_files(out, "--out", only=RESULTS_ENTRIES)
    held = stress.holds_results(out)
    if held and not (args.resume or args.force or args.dry_run):
        raise InputError(f"--out {str(out)!r} already holds results ({held}): pass --resume to continue it "
                         f"(finished runs are kept), or choose another --out")

    tasks = stress.build_grid(names, quick=args.quick, axes=axes, time_limit=tl, max_n=max_n, scene_name=args.scene)
    if args.dry_run:
        from collections import Counter

        for ax, n in Counter(t.axis for t in tasks).items():
            print(f"{ax:6s} {n} runs")
        print(f"total  {len(tasks)} runs, solvers: {', '.join(names)}")
        print(f"time   {_estimate(tasks, jobs)[1]}")
        return 0
    refs = reference.candidates()
    meta = _meta(args, reg, names, axes, tasks, [r[0] for r in refs])
    if args.resume or args.force:      # the folder's meta.json is widened, never replaced
        meta = _merge_meta(out / "meta.json", meta)
    tty = sys.stderr.isatty()
    t0 = time.monotonic()

    def progress(i, n, row):
        err = row.err_x_energy
        e = f"err {err:.1e}" if isinstance(err, float) and math.isfinite(err) else ""
        line = (f"[{i}/{n} {time.monotonic() - t0:6.0f}s] {row.axis:5s} {row.solver:9s} "
                f"{_coords(row.coords):32s} {row.status or '':15s} {row.grade or '':12s} {e}")
        print(("\r" + line[:150]) if tty else line, file=sys.stderr, end="" if tty else "\n", flush=True)

    print(f"dualfem stress: {len(tasks)} runs ({', '.join(names)}), reference "
          f"{refs[0][0] if refs else 'NONE'} -> {out}", file=sys.stderr)
    _say_estimate(tasks, jobs, out if args.resume else None)
    recs = stress.run_grid(tasks, out, jobs=jobs, resume=args.resume, force=args.force,
                           retry_failed=args.retry_failed, progress=progress, meta={**meta},
                           command=meta.get("command") or "")
    if tty:
        print(file=sys.stderr)
    from collections import Counter

    every = stress.load_results(out)[1]  # every record, also of earlier (resumed) runs
    c = Counter(r.grade for r in every)
    stress._write_meta(out, {**meta, "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                             "complete": len(recs) == len(tasks) and meta.get("complete_before", True),
                             "n_tasks": len(tasks), "n_records": len(every),
                             "outcomes": dict(c)})
    print("outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(c.items())), file=sys.stderr)
    print(f"results in {out}/results.csv; report: dualfem report stability {out}", file=sys.stderr)
    return 0


def _estimate(tasks: list, jobs: int) -> tuple[dict | None, str]:
    """The grid's time estimate (:mod:`dualfem.experiments.stress_estimate`) and its line; (None, why)
    when the probe run of the base scene fails (the grid then records that failure run by run)."""
    from dualfem.experiments.stress_estimate import describe, estimate

    try:
        est = estimate(tasks, jobs)
    except Exception as exc:  # noqa: BLE001 - a plugin's or a scene's failure, whatever it raises
        return None, f"no estimate: one run of the base scene failed ({describe_exception(exc)})"
    return est, describe(est)


def _say_estimate(tasks: list, jobs: int, resumed: Path | None) -> None:
    """Before the first run: the estimate on stderr (of the runs a resume has left), and a warning
    line when it exceeds :data:`~dualfem.experiments.stress_estimate.WARN_S`."""
    from dualfem.experiments.stress_estimate import WARN_S, duration

    if resumed is not None:
        done = {p.name[:-5] for p in (resumed / "rows").glob("[!.]*.json")}
        tasks = [t for t in tasks if t.id not in done]
    est, line = _estimate(tasks, jobs)
    print(f"dualfem stress: {line}", file=sys.stderr, flush=True)
    if est is not None and est["seconds"] > WARN_S:
        print(f"dualfem stress: warning: this grid takes about {duration(est['seconds'])}; narrow it with --solvers, "
              f"--axes or --max-n (--dry-run lists the runs per axis); Ctrl-C stops it, --resume continues it",
              file=sys.stderr, flush=True)


def _choice(flag: str, value: str | None, allowed: list[str], what: str, word: str) -> list[str]:
    """The comma-separated names of ``flag`` (default or ``all``: all of ``allowed``), each checked."""
    if not value or value.strip() == "all":
        return list(allowed)
    names = [s.strip() for s in value.split(",") if s.strip()]
    bad = [s for s in names if s not in allowed]
    if bad or not names:
        raise InputError(f"{flag}: unknown {what} {bad[0] if bad else '(empty)'!r}; {word}: {', '.join(allowed)}")
    return names


def _meta(args, reg: dict, names: list[str], axes: tuple, tasks: list, refs: list[str]) -> dict:
    """What meta.json records about the grid: its definition, tolerances, machine, commit."""
    from dualfem.experiments import stress
    from dualfem.experiments.machine import environment

    return {"quick": bool(args.quick), "scene": getattr(args, "scene", None) or "f2 (paper)",
            "solvers": names, "axes": sorted({t.axis for t in tasks}, key=stress.AXES.index),
            "grading": "dualfem.verify.grading: error <= declared tolerance + the reference's certified bound",
            "ref_kkt": stress.REF_KKT, "references": refs,
            "tolerances": {n: reg[n]().tolerance for n in names if reg[n].missing() is None},
            "exact": {n: reg[n].exact for n in names},
            "third_party": {n: bool(reg[n].requires) for n in names},
            "missing": {n: reg[n].missing() for n in names if reg[n].missing()},
            "base": tasks[0].scene if tasks and getattr(args, "scene", None) else stress.BASE,
            "time_limit": tasks[0].time_limit if tasks else None,
            "command": "dualfem " + " ".join(sys.argv[1:]) if sys.argv and "dualfem" in sys.argv[0] else None,
            "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "environment": environment(), "git_commit": _git_head()}


def _coords(c: dict) -> str:
    return " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in c.items())


def _git_head() -> str | None:
    """The commit of the working tree the grid ran on (None outside a git checkout)."""
    import subprocess

    try:
        p = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10,
                           cwd=Path(__file__).resolve().parents[2])
        return p.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def _merge_meta(path: Path, new: dict) -> dict:
    """Meta of a resumed run: the first run's description, widened by this run, with a resume log."""
    import json

    try:
        prev = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(prev, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError):
        if path.is_file():          # unreadable: kept aside (a new name), never overwritten
            from dualfem.core.io import move_aside

            dest = move_aside(path, "corrupt")
            print(f"dualfem stress: warning: unreadable {str(path)!r} moved to {str(dest)!r}; a new one is "
                  f"written", file=sys.stderr)
        return new
    out = dict(prev)
    out["solvers"] = list(dict.fromkeys(list(prev.get("solvers", [])) + list(new["solvers"])))
    out["axes"] = list(dict.fromkeys(list(prev.get("axes", [])) + list(new["axes"])))
    for k in ("tolerances", "exact", "third_party", "missing"):
        out[k] = {**prev.get(k, {}), **new.get(k, {})}
    out["complete_before"] = bool(prev.get("complete", True))
    out["resumed"] = list(prev.get("resumed", [])) + [
        {k: new.get(k) for k in ("started", "command", "git_commit", "solvers", "axes")}]
    out.pop("finished", None)
    out.pop("outcomes", None)
    return out
