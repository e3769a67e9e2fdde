"""``dualfem report KIND [ARGS...]``: regenerate a report in reports/.

Report kinds are registered by the modules of ``dualfem/reports/`` with :func:`register_report`;
each kind is a function ``run(argv: list[str]) -> int`` with its own argparse.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
from collections.abc import Callable

from dualfem.cli.main import command
from dualfem.core.errors import InputError

_REPORTS: dict[str, tuple[str, Callable[[list[str]], int]]] = {}


def register_report(kind: str, help: str):
    """Decorator: register ``run(argv) -> exit code`` as ``dualfem report KIND``."""
    def deco(fn):
        _REPORTS[kind] = (help, fn)
        return fn
    return deco


def reports() -> dict[str, tuple[str, Callable[[list[str]], int]]]:
    """All report kinds (imports every module of ``dualfem/reports/``)."""
    import dualfem.reports

    for info in pkgutil.iter_modules(dualfem.reports.__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"dualfem.reports.{info.name}")
    return dict(_REPORTS)


def _cfg(p):
    p.add_argument("kind", metavar="KIND", help="which report (see 'dualfem report list')")
    p.add_argument("rest", nargs=argparse.REMAINDER, metavar="ARGS",
                   help="arguments of that report (see 'dualfem report KIND --help')")


@command("report", "regenerate a report in reports/ (KIND: paper, bench, figures, ...)")(_cfg)
def cmd_report(args) -> int:
    kinds = reports()
    if args.kind == "list":
        for k, (h, _) in sorted(kinds.items()):
            print(f"{k:12s} {h}")
        return 0
    if args.kind not in kinds:
        raise InputError(f"unknown report {args.kind!r}; known: {', '.join(sorted(kinds)) or '(none)'}")
    return kinds[args.kind][1](list(args.rest))
