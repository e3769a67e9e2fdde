"""Command-line interface: ``dualfem list | export | solve | ...``.

Every input error exits with status 2 and one line on stderr (no traceback). ``--json`` prints
exactly one JSON object on stdout.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

from dualfem.cli.options import (
    OneLineParser,
    add_solver_option,
    deprecated,
    float_in,
    int_in,
    parse_solvers,
    print_deprecations,
    spelled,
)
from dualfem.cli.stages import Stages
from dualfem.core.errors import InputError, MissingDependency, describe_exception

#: the paper's method with r taken from the QP: scale-free (uzawa's r = 1e7 is in MPa per unit length)
DEFAULT_SOLVER = "uzawa_auto"
#: the largest ``--max-memory`` accepted, in GB
MAX_MEMORY_GB = 1e6
_COMMANDS: dict[str, tuple[str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]] = {}
_DESCRIPTIONS: dict[str, str] = {}


def command(name: str, help: str, description: str | None = None):
    """Register a sub-command: decorate ``run(args) -> exit code``; ``configure`` adds options. ``help`` is
    its line in ``dualfem --help``, ``description`` (default: ``help``) the head of ``dualfem NAME --help``."""
    def deco(configure):
        def wrap(run):
            _COMMANDS[name] = (help, configure, run)
            _DESCRIPTIONS[name] = description or help
            return run
        return wrap
    return deco


def add_scene_args(p: argparse.ArgumentParser) -> None:
    """SCENE and ``--set KEY=VALUE`` (shared by every scene-taking command)."""
    p.add_argument("scene", metavar="SCENE", help="built-in scene (f1, f2, f3, ...: see 'dualfem list'), "
                   "a .toml scene file, or a .npz/.mat QP file")
    p.add_argument("--max-memory", type=float_in(0, MAX_MEMORY_GB, "GB"), default=None, metavar="GB",
                   help="memory a run may use, in GB (default: what the machine has available); a scene whose "
                        "estimated peak exceeds it is refused before assembly")
    p.add_argument("--set", dest="set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene parameter (N, delta, plane, E, nu, load, ...)")


def add_factor_arg(p: argparse.ArgumentParser) -> None:
    """``--factor NAME``: the sparse factorization backend (default: $DUALFEM_FACTOR, else the fastest installed)."""
    p.add_argument("--factor", default=None, metavar="NAME",
                   help="factorization backend: pardiso, cholmod or superlu (default: the environment variable "
                        "DUALFEM_FACTOR, else the fastest installed)")


def apply_factor(args: argparse.Namespace) -> str:
    """Choose the run's linear-algebra context from ``--factor``, ``--threads``, ``--max-memory``
    (:func:`dualfem.numerics.la.from_args`; InputError for an unknown/uninstalled backend); its backend.
    Forked workers share it; the bench harness hands it to its child processes."""
    from dualfem.numerics import la

    return la.use(la.from_args(args)).factor


def add_param_args(p: argparse.ArgumentParser) -> None:
    """``-p/--param KEY=VALUE``: a solver parameter, the deprecated spelling of ``-s SOLVER[KEY=VALUE]``
    (still accepted, with a warning; not shown in ``--help``)."""
    p.add_argument("-p", "--param", action="append", default=[], metavar="KEY=VALUE", help=argparse.SUPPRESS)


def add_tol_arg(p: argparse.ArgumentParser) -> None:
    """``--tol T``: the certified tolerance (:mod:`dualfem.experiments.tolerance`)."""
    p.add_argument("--tol", default=None, metavar="T",
                   help="certify the answer to this relative energy-norm error of x, in (0, 1), and ask each solver "
                        "for it (its tolerance_params); default: the solver's declared tolerance. -p tol=... is the "
                        "solver's own stop rule")


def scene_from_args(args: argparse.Namespace):
    """Problem instance from SCENE + --set."""
    from dualfem.core.scene import load_scene, parse_set
    from dualfem.numerics.memory import check_fits

    problem = load_scene(args.scene, parse_set(args.set))
    mm = getattr(args, "max_memory", None)
    if mm is not None and not (mm > 0 and mm <= MAX_MEMORY_GB):
        raise InputError(f"--max-memory must be a number of GB in (0, {MAX_MEMORY_GB:g}], got {mm!r}")
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
    from dualfem.post.style import family

    def describe_solver(c) -> dict:
        return {"installed": c.missing() is None, "missing": c.missing(), "description": c.description,
                "exact": c.exact, "parameters": c.defaults, "allowed": c.allowed(),
                "renamed": dict(getattr(c, "renamed", {})), "family": family(c.name),
                "reference": bool(getattr(c, "reference", False) and c.exact)}

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
        why = f"plugin error: {describe_exception(exc)}"
        return {"installed": False, "missing": why, "description": str(getattr(cls, "description", "")),
                "parameters": {}}


# ------------------------------------------------------------------------- export
def _cfg_export(p):
    add_scene_args(p)
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="output .npz or .mat file (--format fclib: "
                                                                        ".hdf5 or .h5)")
    p.add_argument("--format", choices=("qp", "fclib"), default="qp",
                   help="qp: the QP's arrays (default); fclib: a Coulomb-frictional scene as FCLIB's global problem "
                        "(HDF5: M, H, f, w, mu; docs/friction.md)")
    p.add_argument("--convention", choices=("dualfem", "qpsolvers"), default="dualfem",
                   help="array names: dualfem's own K, F, B (B x >= 0) with the mesh maps (default), or "
                        "qpsolvers' P, q, G, h (G x <= h), the QP alone (docs/export.md)")


@command("export", "write a scene's QP to .npz or .mat")(_cfg_export)
def cmd_export(args) -> int:
    from pathlib import Path

    from dualfem.core.io import check_output_path
    from dualfem.core.scene import build_qp

    if args.format == "fclib":
        from dualfem.cli.export_fclib import export_fclib

        return export_fclib(args)
    if Path(args.output).suffix not in (".npz", ".mat"):
        raise InputError(f"-o must name a .npz or .mat file, got {args.output!r}")
    check_output_path(args.output, "-o")
    qp = build_qp(scene_from_args(args))
    if args.convention == "qpsolvers":
        from dualfem.core.qpfile import qpsolvers_arrays, save_arrays

        save_arrays(args.output, qpsolvers_arrays(qp))
    else:
        qp.save(args.output)
    names = "P, q, G, h: G x <= h" if args.convention == "qpsolvers" else "K, F, B: B x >= 0"
    print(f"wrote {args.output}: n={qp.n} unknowns, m={qp.m} constraints ({names})", file=sys.stderr)
    return 0


# -------------------------------------------------------------------------- solve
def _cfg_solve(p):
    add_scene_args(p)
    add_solver_option(p, f"the solver and its parameters, e.g. -s pdas or -s 'uzawa[r=1e7,tol=1e-9]' (default "
                         f"{DEFAULT_SOLVER}; 'dualfem list --json' shows each solver's parameters and ranges)")
    add_param_args(p)
    add_tol_arg(p)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--vtk", metavar="FILE.vtu", default=None,
                   help="also write the solution for ParaView (displacement, stresses, defect jump/pressure)")
    p.add_argument("--xdmf", metavar="FILE.xdmf", default=None, help="the same as XDMF + HDF5 (needs h5py)")
    p.add_argument("--figure", metavar="FILE.png", default=None,
                   help="also draw the solution (.png/.pdf/.svg): 2D the deformed body and the jump; 3D the "
                        "opening, slip and pressure maps over each defect and a cut through the body (FILE_cut.png)")
    p.add_argument("--sif", action="store_true",
                   help="also compute the stress intensity factors at every tip / front node (the summary's last "
                        "line, --json 'sif', 3D --vtk/--xdmf point fields K_I, K_II, K_III; docs/sif.md)")
    p.add_argument("--threads", type=int_in(1, max_threads()), default=None, metavar="N",
                   help="threads for the factorization (default: all cores; dense phases use what is fastest)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    add_factor_arg(p)


@command("solve", "solve one scene with one solver")(_cfg_solve)
def cmd_solve(args) -> int:
    from dualfem.core.registry import get_solver
    from dualfem.experiments.runner import make_solver, missing_reason
    from dualfem.experiments.tolerance import check_tol, with_tolerance

    tol = check_tol(args.tol)
    name, given = solve_choice(args)
    solver = make_solver(name, with_tolerance(get_solver(name), tol, given))  # validate before the (slow) assembly
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

    rec, solved = solve_guarded(args, solver, stages, tol, given)      # build, solve, outputs: under the watchdog
    rec["factor"] = factor
    rec["threads"] = threads
    if args.json:
        print(dumps(rec))
    else:
        print(human_summary(rec, scene=args.scene))
    return 0 if solved else 1


def solve_choice(args: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    """The one solver of ``solve``: ``-s SOLVER[KEY=V,...]`` (default :data:`DEFAULT_SOLVER`), plus the
    deprecated ``-p KEY=V`` (merged; a key given both ways is refused)."""
    from dualfem.core.scene import parse_set

    chosen = parse_solvers(args.solver) or [(DEFAULT_SOLVER, {})]
    if len(chosen) > 1:
        raise InputError(f"-s/--solver: 'dualfem solve' runs one solver, got {len(chosen)} "
                         f"({', '.join(n for n, _ in chosen)}): 'dualfem compare' runs several")
    name, params = chosen[0]
    old = parse_set(args.param, "-p")
    both = sorted(set(old) & set(params))
    if both:
        raise InputError(f"-p {both[0]}=... and -s {name}[{both[0]}=...] both set {both[0]!r}: give it once, in -s")
    if old:
        deprecated(args, f"-p KEY=VALUE is deprecated: write -s {spelled(name, {**params, **old})}")
    return name, {**params, **old}


def max_threads() -> int:
    """The largest ``--threads``: 4 x the cores of this machine."""
    import os

    return 4 * (os.cpu_count() or 1)


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


def human_summary(rec: dict, scene: str | None = None) -> str:
    """A few lines for a person; ``scene``: the scene as the user named it (a scene file by its stem),
    shown instead of the QP's internal name (``curved``, not ``thin_defect[f2]``)."""
    from pathlib import Path

    name = (Path(scene).stem if scene.endswith((".toml", ".npz", ".mat")) else scene) if scene else rec["problem"]
    lines = [f"{name}: {rec['ndof']} unknowns, {rec['n_defect_nodes']} defect nodes",
             f"solver {rec['solver']}: {rec['status']}  {rec['message']}",
             f"iterations {rec['iterations']}  " + _times(rec['time_s'])]
    if rec.get("residuals"):
        r = rec["residuals"]
        lines.append(f"energy {rec['energy']:.10g}  max jump {rec['max_jump']:.4g}  "
                     f"contact nodes {rec['n_contact']}/{rec['n_defect_nodes']}")
        for f in rec.get("friction", ()):
            lines.append(f"friction ({f['law']}): {f['slipping']}/{f['nodes']} nodes slip, "
                         f"max slip {f['max_slip']:.4g}")
        lines.append("residuals (evaluator): " + "  ".join(f"{k} {v:.2e}" for k, v in r.items()))
    if rec.get("sif"):
        from dualfem.post.sif_outputs import summary_line

        lines.append(summary_line(rec["sif"]))
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
    parser = OneLineParser(prog="dualfem", description="dualfem: the thin-defect crack model as a convex QP, solved "
                           "by interchangeable solvers and certified by an evaluator that trusts none of them "
                           "('dualfem COMMAND --help' for each command)")
    parser.add_argument("--version", action="version", version=f"dualfem {version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (help_, configure, _) in _COMMANDS.items():
        sp = sub.add_parser(name, help=help_, description=_DESCRIPTIONS.get(name, help_))
        configure(sp)
        try:        # every command: the third-party libraries' own output (dualfem.core.quiet)
            sp.add_argument("--verbose", action="store_true",
                            help="let the solvers' libraries print their own banners and logs on stderr "
                                 "(dropped by default)")
        except argparse.ArgumentError:      # the command has its own --verbose
            pass
    return parser


def version() -> str:
    """The installed distribution's version (its metadata), else the package's ``__version__``."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("dualfem")
    except PackageNotFoundError:     # a source tree that was never installed: the version it declares
        import tomllib
        from pathlib import Path

        try:
            meta = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text("utf-8"))
            return str(meta["project"]["version"])
        except (OSError, KeyError, tomllib.TOMLDecodeError):
            return "unknown"


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
        args, extra = parser.parse_known_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    if extra:                    # named by the command they were given to, as its other errors are
        print(f"dualfem {args.command}: error: unrecognized arguments: {' '.join(extra)} (see 'dualfem "
              f"{args.command} --help')", file=sys.stderr)
        return 2
    if "stdout" in closed and getattr(args, "json", False):
        print(f"dualfem {args.command}: error: the standard output is closed: nowhere to write the JSON "
              f"object of --json", file=sys.stderr)
        return EXIT_NO_STDOUT
    run = _COMMANDS[args.command][2]
    if getattr(args, "verbose", False) is True:
        from dualfem.core.quiet import set_verbose

        set_verbose(True)
    from dualfem.numerics import la

    before = la.chosen()         # the command's linear-algebra context ends with it (in-process callers)
    try:
        rc = run(args)
        sys.stdout.flush()       # a full disk behind `> file` shows here, not at interpreter exit
        print_deprecations(args)
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
    finally:
        la.use(before)


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
