"""``dualfem compare SCENE [--set KEY=VALUE ...] [-s SOLVER[KEY=V,...] ...] [--json]``.

Runs every registered solver (or the ones chosen with ``-s``, repeatable, each with its parameters:
``-s pdas -s 'osqp[tol=1e-6,polish=true]'``) on one scene and cross-checks them against a certified
reference (see :mod:`dualfem.experiments.compare`). Exit status: 0 unless a solver that claims
success is wrong beyond its declared tolerance (a silent wrong answer: exit 1); input errors
exit 2. The deprecated forms ``--solvers A,B`` and ``--param SOLVER.KEY=VALUE`` still work (with a
warning).
Solver output written by C libraries to stdout is sent to stderr, so ``--json`` prints exactly
one JSON object on stdout; one progress line per finished solver goes to stderr.
"""
from __future__ import annotations

import argparse
import sys
from typing import Any

from dualfem.cli.main import add_factor_arg, add_scene_args, add_tol_arg, apply_factor, command, dumps, scene_from_args
from dualfem.cli.options import add_solver_option, deprecated, parse_solvers, spelled
from dualfem.core.errors import InputError


def _cfg(p):
    add_factor_arg(p)
    add_scene_args(p)
    add_solver_option(p, "a solver to run, with its parameters, e.g. -s pdas -s 'osqp[tol=1e-6]' (repeatable; "
                         "default: every registered solver)")
    # deprecated spellings (still accepted, with a warning): --solvers A,B and -p SOLVER.KEY=VALUE
    p.add_argument("--solvers", default=None, metavar="A,B,...", help=argparse.SUPPRESS)
    p.add_argument("-p", "--param", action="append", default=[], metavar="SOLVER.KEY=VALUE", help=argparse.SUPPRESS)
    add_tol_arg(p)
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


def compare_choice(args: argparse.Namespace) -> tuple[list[str], dict[str, dict[str, Any]]]:
    """The solvers of ``compare`` and their parameters: ``-s`` (one parser for every command), else the
    deprecated ``--solvers``, else every registered solver; plus the deprecated ``-p SOLVER.KEY=V``."""
    from dualfem.core.registry import get_solver
    from dualfem.experiments.compare import default_solvers

    if args.solver and args.solvers is not None:
        raise InputError("-s/--solver and --solvers both choose the solvers: give them with -s only")
    chosen = parse_solvers(args.solver)
    if args.solvers is not None:
        names = [s.strip() for s in args.solvers.split(",") if s.strip()]
        if not names:
            raise InputError("--solvers needs at least one solver name")
        if len(set(names)) != len(names):
            raise InputError(f"--solvers lists a solver twice: {args.solvers!r}")
        chosen = [(n, {}) for n in names]
    for nm, _ in chosen:
        try:
            get_solver(nm)  # InputError listing the known names
        except InputError as exc:
            raise InputError(f"{'--solvers' if args.solvers is not None else '-s/--solver'}: {exc}") from None
    names = [n for n, _ in chosen] or default_solvers()
    params = {n: dict(p) for n, p in chosen if p}
    for nm, old in parse_solver_params(args.param, names).items():
        both = sorted(set(old) & set(params.get(nm, {})))
        if both:
            raise InputError(f"-p {nm}.{both[0]}=... and -s {nm}[{both[0]}=...] both set {both[0]!r}: give it once")
        params[nm] = {**params.get(nm, {}), **old}
    if args.solvers is not None or args.param:
        new = " ".join(f"-s {spelled(n, params.get(n, {}))}" for n in names)
        deprecated(args, f"--solvers A,B and -p SOLVER.KEY=VALUE are deprecated: write {new}")
    return names, params


@command("compare", "run several solvers on one scene and cross-check them against a certified reference")(_cfg)
def cmd_compare(args) -> int:
    apply_factor(args)
    from dualfem.cli.launch import compare_guarded
    from dualfem.experiments.compare import stderr_progress, table
    from dualfem.experiments.runner import make_solver
    from dualfem.experiments.tolerance import check_tol

    tol = check_tol(args.tol)
    names, params = compare_choice(args)
    for nm, prm in params.items():
        make_solver(nm, prm)        # a bad parameter is refused before the (slow) assembly
    scene_from_args(args)            # bad scene parameters: one line, before any worker starts
    result, why = compare_guarded(args, names, params, progress=stderr_progress(), tol=tol)   # under the watchdog
    if result is None:
        print(f"dualfem compare: {why}", file=sys.stderr)
        return 1
    if args.json:
        print(dumps(result))
    else:
        print(table(result, scene=args.scene))
    return 1 if result["silent_wrong"] else 0
