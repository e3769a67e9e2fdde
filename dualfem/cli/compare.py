"""``dualfem compare SCENE [--set KEY=VALUE ...] [--solvers a,b,...] [--json]``.

Runs every registered solver (or the chosen ones) on one scene and cross-checks them against a
certified reference (see :mod:`dualfem.experiments.compare`). Exit status: 0 unless a solver that claims
success is wrong beyond its declared tolerance (a silent wrong answer: exit 1); input errors
exit 2. Solver parameters: ``--param SOLVER.KEY=VALUE`` (e.g. ``--param osqp.eps_abs=1e-6``).
Solver output written by C libraries to stdout is sent to stderr, so ``--json`` prints exactly
one JSON object on stdout; one progress line per finished solver goes to stderr.
"""
from __future__ import annotations

import sys

from dualfem.cli.main import add_factor_arg, add_scene_args, apply_factor, command, dumps, scene_from_args
from dualfem.core.errors import InputError


def _cfg(p):
    add_factor_arg(p)
    add_scene_args(p)
    p.add_argument("--solvers", default=None, metavar="A,B,...",
                   help="comma-separated solver names (default: every registered solver)")
    p.add_argument("-p", "--param", action="append", default=[], metavar="SOLVER.KEY=VALUE",
                   help="set a parameter of one solver, e.g. osqp.eps_abs=1e-6 (repeatable)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def parse_solver_params(items: list[str], names: list[str]) -> dict[str, dict[str, str]]:
    """``SOLVER.KEY=VALUE`` strings -> {solver: {key: value}}; InputError when malformed."""
    out: dict[str, dict[str, str]] = {}
    for item in items or []:
        lhs, sep, value = item.partition("=")
        solver, dot, key = lhs.partition(".")
        if not sep or not dot or not solver.strip() or not key.strip():
            raise InputError(f"--param expects SOLVER.KEY=VALUE, got {item!r}")
        solver = solver.strip()
        if solver not in names:
            raise InputError(f"--param {item!r}: solver {solver!r} is not among the compared solvers "
                             f"({', '.join(names)})")
        out.setdefault(solver, {})[key.strip()] = value.strip()
    return out


@command("compare", "run several solvers on one scene and cross-check them against a certified reference")(_cfg)
def cmd_compare(args) -> int:
    apply_factor(args)
    from dualfem.cli.launch import compare_guarded
    from dualfem.core.registry import get_solver
    from dualfem.experiments.compare import default_solvers, stderr_progress, table

    if args.solvers is not None:
        names = [s.strip() for s in args.solvers.split(",") if s.strip()]
        if not names:
            raise InputError("--solvers needs at least one solver name")
        for nm in names:
            get_solver(nm)  # InputError listing the known names
        if len(set(names)) != len(names):
            raise InputError(f"--solvers lists a solver twice: {args.solvers!r}")
    else:
        names = default_solvers()
    params = parse_solver_params(args.param, names)
    scene_from_args(args)            # bad scene parameters: one line, before any worker starts
    result, why = compare_guarded(args, names, params, progress=stderr_progress())   # under the watchdog
    if result is None:
        print(f"dualfem compare: {why}", file=sys.stderr)
        return 1
    if args.json:
        print(dumps(result))
    else:
        print(table(result))
    return 1 if result["silent_wrong"] else 0
