"""Command-line interface: ``dualfem list | export | solve | ...``.

Every input error exits with status 2 and one line on stderr (no traceback). ``--json`` prints
exactly one JSON object on stdout.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

from dualfem.cli.stages import Stages
from dualfem.core.errors import InputError, MissingDependency

#: the paper's method with r taken from the QP: scale-free (uzawa's r = 1e7 is in MPa per unit length)
DEFAULT_SOLVER = "uzawa_auto"
_COMMANDS: dict[str, tuple[Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]] = {}


def command(name: str, help: str):
    """Register a sub-command: decorate ``run(args) -> exit code``; ``configure`` adds options."""
    def deco(configure):
        def wrap(run):
            _COMMANDS[name] = (help, configure, run)
            return run
        return wrap
    return deco


def add_scene_args(p: argparse.ArgumentParser) -> None:
    """SCENE and ``--set KEY=VALUE`` (shared by every scene-taking command)."""
    p.add_argument("scene", metavar="SCENE", help="built-in scene (f1, f2, f3, ...: see 'dualfem list'), "
                   "a .toml scene file, or a .npz/.mat QP file")
    p.add_argument("--max-memory", type=float, default=None, metavar="GB",
                   help="memory a run may use (default: what the machine has available); a scene whose "
                        "estimated peak exceeds it is refused before assembly")
    p.add_argument("--set", dest="set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene parameter (N, delta, plane, E, nu, load, ...)")


def add_factor_arg(p: argparse.ArgumentParser) -> None:
    """``--factor NAME``: the sparse factorization backend (default: $DUALFEM_FACTOR, else the fastest installed)."""
    p.add_argument("--factor", default=None, metavar="NAME",
                   help="factorization backend: pardiso, cholmod or superlu (default: the environment variable "
                        "DUALFEM_FACTOR, else the fastest installed)")


def apply_factor(args: argparse.Namespace) -> str:
    """Make ``--factor`` the process-wide backend (and the one worker processes inherit); its name."""
    import os

    from dualfem.numerics.factor import get_default, set_default

    if getattr(args, "factor", None):
        set_default(args.factor)                       # InputError for an unknown/uninstalled name
        os.environ["DUALFEM_FACTOR"] = get_default()
    return get_default()


def add_param_args(p: argparse.ArgumentParser) -> None:
    """``--param KEY=VALUE`` for solver parameters."""
    p.add_argument("-p", "--param", action="append", default=[], metavar="KEY=VALUE",
                   help="set a solver parameter (e.g. r=1e7, tol_outer=1e-5)")


def scene_from_args(args: argparse.Namespace):
    """Problem instance from SCENE + --set."""
    from dualfem.core.scene import load_scene, parse_set
    from dualfem.numerics.memory import check_fits

    problem = load_scene(args.scene, parse_set(args.set))
    mm = getattr(args, "max_memory", None)
    if mm is not None and not (mm > 0 and mm < 1e6):
        raise InputError(f"--max-memory must be a number of GB in (0, 1e6), got {mm!r}")
    check_fits(problem, None if mm is None else mm * 1e9)     # before any allocation
    return problem


def dumps(obj: Any) -> str:
    """The JSON output of every command: :func:`dualfem.core.io.dumps` (imported lazily: cheap start-up)."""
    from dualfem.core.io import dumps as _dumps

    return _dumps(obj)


# --------------------------------------------------------------------------- list
def _cfg_list(p):
    p.add_argument("--json", action="store_true", help="print one JSON object")


@command("list", "list problems, scenes and solvers (and whether each is installed)")(_cfg_list)
def cmd_list(args) -> int:
    from dualfem.core.quiet import plugin_output
    from dualfem.core.registry import entry_point_errors, problems, solvers
    from dualfem.core.scene import describe, library, preset_conflicts, presets

    def describe_solver(c) -> dict:
        return {"installed": c.missing() is None, "missing": c.missing(), "description": c.description,
                "exact": c.exact, "parameters": c.defaults, "allowed": c.allowed(),
                "renamed": dict(getattr(c, "renamed", {}))}

    def describe_problem(c) -> dict:
        return {"description": c.description, "installed": c.missing() is None, "missing": c.missing(),
                "parameters": {k: str(v) for k, v in c.defaults.items()}}

    with plugin_output():                 # a plugin's classmethods may print: --json stays one object
        sol = {n: _plugin_info(describe_solver, c) for n, c in sorted(solvers().items())}
        prb = {n: _plugin_info(describe_problem, c) for n, c in sorted(problems().items())}
    scn = {n: {"problem": pn, **{k: str(v) for k, v in prm.items()}} for n, (pn, prm) in sorted(presets().items())}
    lib = {n: {"file": str(p), "description": describe(p)} for n, p in library().items()}
    errors = entry_point_errors() + preset_conflicts()
    if args.json:
        print(dumps({"problems": prb, "scenes": scn, "scene_library": lib, "solvers": sol,
                     "plugin_errors": errors}))
        return 0
    print("problems:")
    for n, d in prb.items():
        print(f"  {n:14s} {d['description']}" + ("" if d["installed"] else f" NOT INSTALLED ({d['missing']})"))
    print("scenes:")
    for n, d in scn.items():
        print(f"  {n:14s} {d}")
    print("scene library (dualfem solve NAME):")
    for n, d in lib.items():
        print(f"  {n:14s} {d['description']}")
    print("solvers:")
    for n, d in sol.items():
        state = "installed" if d["installed"] else f"NOT INSTALLED ({d['missing']})"
        print(f"  {n:14s} {state:10s} {d['description']}")
    for e in entry_point_errors():
        print(f"  plugin failed to load: {e}")
    for e in preset_conflicts():
        print(f"  plugin preset refused: {e}")
    return 0


def _plugin_info(describe: Callable[[Any], dict], cls: Any) -> dict:
    """``describe(cls)``, or, when a plugin's classmethod raises (anything but a real Ctrl-C), a record
    saying so: ``dualfem list`` shows every other plugin."""
    try:
        return describe(cls)
    except BaseException as exc:  # noqa: BLE001 - a third-party plugin's bug
        if type(exc) is KeyboardInterrupt:
            raise
        why = f"plugin error: {type(exc).__name__}: {exc}"
        return {"installed": False, "missing": why, "description": str(getattr(cls, "description", "")),
                "parameters": {}}


# ------------------------------------------------------------------------- export
def _cfg_export(p):
    add_scene_args(p)
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="output .npz or .mat file")


@command("export", "write a scene's QP to .npz or .mat")(_cfg_export)
def cmd_export(args) -> int:
    from pathlib import Path

    from dualfem.core.io import check_output_path
    from dualfem.core.scene import build_qp

    if Path(args.output).suffix not in (".npz", ".mat"):
        raise InputError(f"-o must name a .npz or .mat file, got {args.output!r}")
    check_output_path(args.output, "-o")
    qp = build_qp(scene_from_args(args))
    qp.save(args.output)
    print(f"wrote {args.output}: n={qp.n} unknowns, m={qp.m} constraints", file=sys.stderr)
    return 0


# -------------------------------------------------------------------------- solve
def _cfg_solve(p):
    add_scene_args(p)
    p.add_argument("--solver", default=DEFAULT_SOLVER, help=f"solver name (default {DEFAULT_SOLVER})")
    add_param_args(p)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--vtk", metavar="FILE.vtu", default=None,
                   help="also write the solution for ParaView (displacement, stresses, defect jump/pressure)")
    p.add_argument("--xdmf", metavar="FILE.xdmf", default=None, help="the same as XDMF + HDF5 (needs h5py)")
    p.add_argument("--figure", metavar="FILE.png", default=None,
                   help="also draw the solution (.png/.pdf/.svg): 2D the deformed body and the jump; 3D the "
                        "opening, slip and pressure maps over each defect and a cut through the body (FILE_cut.png)")
    p.add_argument("--threads", type=int, default=None, metavar="N",
                   help="threads for the factorization (default: all cores; dense phases use what is fastest)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    add_factor_arg(p)


@command("solve", "solve one scene with one solver")(_cfg_solve)
def cmd_solve(args) -> int:
    from dualfem.core.scene import parse_set
    from dualfem.experiments.runner import make_solver, missing_reason

    solver = make_solver(args.solver, parse_set(args.param, "-p"))  # validate before the (slow) assembly
    missing = missing_reason(solver)
    if missing:
        raise MissingDependency(missing)
    if args.vtk or args.xdmf:
        from dualfem.post.vtk import check_path

        for path, kind in ((args.vtk, "vtu"), (args.xdmf, "xdmf")):
            if path:
                check_path(path, kind)
    if args.figure:
        from dualfem.post.solution_figure import check_figure_path

        check_figure_path(args.figure)
    from dualfem.numerics.threads import set_threads

    factor = apply_factor(args)
    threads = set_threads(check_threads(args.threads))
    stages = Stages("solve", quiet=args.quiet)
    from dualfem.cli.launch import solve_guarded

    rec, solved = solve_guarded(args, solver, stages)      # build, solve, outputs: under the watchdog
    rec["factor"] = factor
    rec["threads"] = threads
    if args.json:
        print(dumps(rec))
    else:
        print(human_summary(rec))
    return 0 if solved else 1


def check_threads(n: int | None) -> int:
    """The thread count of ``--threads`` (default: every core of this machine), validated."""
    import os

    cores = os.cpu_count() or 1
    if n is None:
        return cores
    if not 1 <= n <= 4 * cores:
        raise InputError(f"--threads must be an integer in 1..{4 * cores} (4 x the {cores} cores), got {n}")
    return n


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, in MB (Linux ru_maxrss is in KB)."""
    import resource

    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)


def human_summary(rec: dict) -> str:
    """A few lines for a person."""
    lines = [f"{rec['problem']}: {rec['ndof']} unknowns, {rec['n_defect_nodes']} defect nodes",
             f"solver {rec['solver']}: {rec['status']}  {rec['message']}",
             f"iterations {rec['iterations']}  " + _times(rec['time_s'])]
    if rec.get("residuals"):
        r = rec["residuals"]
        lines.append(f"energy {rec['energy']:.10g}  max jump {rec['max_jump']:.4g}  "
                     f"contact nodes {rec['n_contact']}/{rec['n_defect_nodes']}")
        lines.append("residuals (evaluator): " + "  ".join(f"{k} {v:.2e}" for k, v in r.items()))
    return "\n".join(lines)


def _times(t: dict) -> str:
    """``time setup S s, solve S s`` (or the seconds until a killed run was stopped)."""
    if "setup" in t and "solve" in t:
        return f"time setup {t['setup']:.3g} s, solve {t['solve']:.3g} s"
    return f"stopped after {t.get('total', float('nan')):.3g} s"


# --------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    """The argparse parser with every registered sub-command."""
    _import_commands()
    parser = argparse.ArgumentParser(prog="dualfem", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (help_, configure, _) in _COMMANDS.items():
        configure(sub.add_parser(name, help=help_, description=help_))
    return parser


def _import_commands() -> None:
    """Import every module of ``dualfem/cli/``: each registers sub-commands with :func:`command`."""
    import importlib
    import pkgutil

    import dualfem.cli

    for info in pkgutil.iter_modules(dualfem.cli.__path__):
        if info.name != "main":
            importlib.import_module(f"dualfem.cli.{info.name}")


#: exit status of ``--json`` with a closed standard output (``dualfem solve ... --json >&-``)
EXIT_NO_STDOUT = 2


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status."""
    closed = _open_std_streams()
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    if "stdout" in closed and getattr(args, "json", False):
        print(f"dualfem {args.command}: error: the standard output is closed: nowhere to write the JSON "
              f"object of --json", file=sys.stderr)
        return EXIT_NO_STDOUT
    run = _COMMANDS[args.command][2]
    try:
        rc = run(args)
        sys.stdout.flush()       # a full disk behind `> file` shows here, not at interpreter exit
        return rc
    except (InputError, MissingDependency) as exc:
        print(f"dualfem {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except ImportError as exc:   # a module imported on the way is missing or broken (e.g. scikit-fem)
        from dualfem.core.errors import install_hint

        msg = (f"the Python module {exc.name!r} is missing or cannot be imported: {install_hint(exc.name)}"
               if exc.name else f"an import failed: {exc}")
        print(f"dualfem {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"dualfem {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:      # the reader of our output went away (e.g. `| head`): stop quietly
        _drop_stdout()
        return 141
    except OSError as exc:       # the disk is full, a file vanished or became unreadable mid-run
        what = exc.strerror or str(exc)
        _drop_stdout()
        msg = (f"cannot access {str(exc.filename)!r}: {what}" if exc.filename
               else f"{what} (writing the standard output or an output file)")
        print(f"dualfem {args.command}: error: {msg}", file=sys.stderr)
        return 2


def _open_std_streams() -> list[str]:
    """Reopen a closed stdout or stderr (``>&-``, ``2>&-``) on /dev/null, at the descriptor level (so
    that no file dualfem opens later takes descriptor 1 or 2 and receives a library's prints) and at
    Python's (``sys.stdout`` is None then: ``print`` would drop, ``flush`` would raise). Returns the
    names of the streams that were closed."""
    import os

    closed = []
    for fd, name in ((1, "stdout"), (2, "stderr")):
        try:
            os.fstat(fd)
            fd_open = True
        except OSError:
            fd_open = False
        if not fd_open:
            null = os.open(os.devnull, os.O_WRONLY)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
        if not fd_open or getattr(sys, name) is None:
            closed.append(name)
            if getattr(sys, name) is None:
                setattr(sys, name, open(os.devnull, "w", encoding="utf-8"))  # noqa: SIM115 - for the process
    return closed


def _drop_stdout() -> bool:
    """Flush stdout; if that fails (its reader is gone or its disk is full) discard what is still
    buffered, so that the interpreter's exit does not fail again. Returns whether the flush worked."""
    import io
    import os

    try:
        sys.stdout.flush()
        return True
    except OSError:
        pass
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, io.UnsupportedOperation):  # not a real file (e.g. captured by a test)
        pass
    return False


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
