"""``dualfem report KIND [ARGS...]``: write a report (where each kind writes by default:
:data:`DEFAULT_OUTPUT`, shown by ``dualfem report --help``).

Report kinds are registered by the modules of ``dualfem/cli/reports/`` with :func:`register_report`;
each kind is a function ``run(argv: list[str]) -> int`` with its own argparse, which runs the
study through :mod:`dualfem.experiments` (or reads the results a study wrote) and then calls a
renderer of :mod:`dualfem.reports` (renderers only read results and write Markdown and figures;
they import nothing from the cli).
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
    """All report kinds (imports every module of ``dualfem/cli/reports/``)."""
    import dualfem.cli.reports

    for info in pkgutil.iter_modules(dualfem.cli.reports.__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"dualfem.cli.reports.{info.name}")
    return dict(_REPORTS)


def _cfg(p):
    p.add_argument("kind", metavar="KIND", help="which report ('dualfem report list' says what each one is)")
    p.add_argument("rest", nargs=argparse.REMAINDER, metavar="ARGS",
                   help="arguments of that report (see 'dualfem report KIND --help')")


#: where each report kind writes by default (each kind's own --help says the same; tests/test_cli.py checks it)
DEFAULT_OUTPUT = {"bench": "dualfem-results/reports/benchmark.md", "html": "dualfem-results/reports/dashboard",
                  "paper": "dualfem-results/reports/paper_tables.md", "figures": "dualfem-results/reports",
                  "plugins": "dualfem-results/reports", "convergence": "dualfem-results/reports",
                  "friction": "dualfem-results/reports",
                  "stability": "reports/stability.md", "robustness": "--out DIR (required)"}


@command("report", "write a report from a study's results (KIND: 'dualfem report list')",
         "write a report from a study's results; default outputs: " +
         ", ".join(f"{k} {v}" for k, v in DEFAULT_OUTPUT.items()) +
         " ('dualfem report KIND --help' for its options)")(_cfg)
def cmd_report(args) -> int:
    kinds = reports()
    if args.kind == "list":
        for k, (h, _) in sorted(kinds.items()):
            print(f"{k:12s} {h}")
        return 0
    if args.kind not in kinds:
        raise InputError(f"unknown report {args.kind!r}; known: {', '.join(sorted(kinds)) or '(none)'}")
    return kinds[args.kind][1](list(args.rest))
