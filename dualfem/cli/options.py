"""Options shared by the commands.

* Numeric option types (:func:`int_in`, :func:`float_in`): a bad value is refused by argparse in one
  line, ``dualfem CMD: error: argument OPTION: must be ... in RANGE, got 'VALUE'`` (exit 2), naming the
  option and its allowed range (the one-line form is :class:`OneLineParser`'s).
* The solver selection ``-s SOLVER[KEY=V,...]`` of ``solve``, ``compare`` and ``bench``: parsed by the one
  parser :func:`dualfem.experiments.spec_select.parse_pick`; each ``KEY=V`` is a parameter of that solver,
  validated by its constructor (the error names the allowed keys and ranges).
* Deprecated forms (``solve -p``, ``compare --solvers``/``-p SOLVER.KEY=V``) keep working; :func:`deprecated`
  records a warning that :func:`dualfem.cli.main.main` prints on stderr once the command has run (an
  input error stays one line).
"""
from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from typing import Any

#: the metavar and help of ``-s`` (the same words in every command)
SOLVER_METAVAR = "SOLVER[KEY=V,...]"


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line on stderr (exit 2), not the usage text."""

    def error(self, message: str):  # type: ignore[override]
        import re

        message = re.sub(r"^argument (\S+): must ", r"\1 must ", message)   # "-r/--repeats must be ..."
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def int_in(lo: int, hi: int) -> Callable[[str], int]:
    """An argparse type: an integer in ``lo..hi`` (inclusive)."""
    def parse(text: str) -> int:
        try:
            value = int(text.strip())
        except (ValueError, AttributeError):
            value = None
        if value is None or not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be an integer in {lo}..{hi}, got {text!r}")
        return value
    parse.__name__ = f"integer in {lo}..{hi}"
    return parse


def float_in(lo: float, hi: float, unit: str = "") -> Callable[[str], float]:
    """An argparse type: a finite number in the open-closed interval ``(lo, hi]``; ``unit`` names its unit
    in the message (e.g. ``"GB"``)."""
    what = f"a number{' of ' + unit if unit else ''} in ({lo:g}, {hi:g}]"

    def parse(text: str) -> float:
        try:
            value = float(text.strip())
        except (ValueError, AttributeError):
            value = math.nan
        if not (math.isfinite(value) and lo < value <= hi):
            raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
        return value
    parse.__name__ = what
    return parse


def add_solver_option(p: argparse.ArgumentParser, help: str, default: Any = None) -> None:
    """``-s/--solver SOLVER[KEY=V,...]`` (repeatable; each command says how many it takes)."""
    p.add_argument("-s", "--solver", action="append", default=default, metavar=SOLVER_METAVAR, help=help)


def parse_solvers(values: list[str] | str | None, option: str = "-s/--solver") -> list[tuple[str, dict[str, Any]]]:
    """``-s`` values -> ``[(solver name, {key: value})]`` (one parser for every command); a solver named
    twice is refused."""
    from dualfem.core.errors import InputError
    from dualfem.experiments.spec_select import parse_pick, solver_params

    out: list[tuple[str, dict[str, Any]]] = []
    for text in [values] if isinstance(values, str) else values or ():      # one name (a Python caller)
        pick = parse_pick(text, option)
        if any(pick.name == name for name, _ in out):
            raise InputError(f"{option} names the solver {pick.name!r} twice (give its parameters in one "
                             f"{pick.name}[KEY=V,...])")
        out.append((pick.name, solver_params(pick, option)))
    return out


def spelled(name: str, params: dict[str, Any]) -> str:
    """The ``-s`` spelling of a solver and its parameters, shell-quoted when it has any (for messages)."""
    import json
    import shlex

    if not params:
        return name
    words = (f"{k}={v if isinstance(v, str) else json.dumps(v)}" for k, v in params.items())   # TOML spelling
    return shlex.quote(f"{name}[{','.join(words)}]")


def deprecated(args: argparse.Namespace, message: str) -> None:
    """Record a deprecation warning for this command line (printed once the command has run)."""
    notes = getattr(args, "_deprecations", None)
    if notes is None:
        notes = []
        args._deprecations = notes
    if message not in notes:
        notes.append(message)


def print_deprecations(args: argparse.Namespace) -> None:
    """Print the recorded deprecation warnings on stderr, one line each."""
    for message in getattr(args, "_deprecations", None) or ():
        print(f"dualfem {args.command}: warning: {message}", file=sys.stderr)
