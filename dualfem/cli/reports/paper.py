"""``dualfem report paper``: the paper's Tables 1-3 beside our k / m (reports/paper_tables.md).

Runs :func:`dualfem.experiments.paper.collect`, stores its data in the ``--data`` JSON (default:
the ``--out`` path with ``.json``), then renders with :func:`dualfem.reports.paper.render`;
``--render-only`` reads the stored data and runs nothing.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from dualfem.cli.options import OneLineParser
from dualfem.cli.report import register_report
from dualfem.core.errors import InputError, describe_exception

#: the top level of the data JSON the renderer reads: key -> type
_DATA = {"Ns": list, "planes": list, "tables": list, "auto": dict, "elapsed_s": (int, float)}


def _check_data(data, where: str) -> None:
    """Refuse data that is not what ``dualfem report paper`` writes (its top-level keys and types, the
    tables' records), before anything is rendered."""
    if not isinstance(data, dict):
        raise InputError(f"{where} is not the JSON object 'dualfem report paper' writes")
    for k, t in _DATA.items():
        if not isinstance(data.get(k), t) or isinstance(data.get(k), bool):
            raise InputError(f"{where} is not what 'dualfem report paper' writes: {k!r} must be "
                             f"{'/'.join(x.__name__ for x in (t if isinstance(t, tuple) else (t,)))}")
    if not data["Ns"] or not data["planes"] or not data["tables"] or \
            not all(isinstance(r, dict) and {"N", "plane", "load", "delta", "k", "status"} <= set(r)
                    for r in data["tables"]):
        raise InputError(f"{where}: 'Ns', 'planes' and 'tables' must be non-empty, every table record with N, "
                         "plane, load, delta, k and status")


def _ints(text: str) -> list[int]:
    try:
        vals = [int(n) for n in text.split(",") if n.strip()]
    except ValueError:
        raise InputError(f"--N must be comma-separated integers >= 4, got {text!r}") from None
    if not vals or min(vals) < 4:
        raise InputError(f"--N must be comma-separated integers >= 4, got {text!r}")
    return vals


@register_report("paper", "the paper's Tables 1-3 beside our k / m (reports/paper_tables.md)")
def report_paper(argv: list[str]) -> int:
    from dualfem.core.io import atomic_write_text
    from dualfem.reports.paper import render

    ap = OneLineParser(prog="dualfem report paper")
    ap.add_argument("--N", default="16,32,64,128,256", help="comma-separated mesh sizes")
    ap.add_argument("--inner-N", default=None, help="mesh sizes of the inner stop test study (default: N <= 128)")
    ap.add_argument("--out", default="dualfem-results/reports/paper_tables.md",
                    help="output (default dualfem-results/reports/paper_tables.md; reports/paper_tables.md for the "
                         "committed one)")
    ap.add_argument("--data", default=None, help="data JSON (default: the --out path with .json)")
    ap.add_argument("--render-only", action="store_true", help="re-render from the data JSON, run nothing")
    args = ap.parse_args(argv)
    data_path = Path(args.data) if args.data else Path(args.out).with_suffix(".json")
    if args.render_only:
        from dualfem.core.io import check_input_path

        check_input_path(data_path, "--data")           # a FIFO or a device: refused before it is opened
        try:
            data = json.loads(data_path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise InputError(f"--data {str(data_path)!r}: cannot read it: {exc}") from None
        _check_data(data, f"--data {str(data_path)!r}")
        command = data.get("command", "dualfem report paper")
    else:
        from dualfem.experiments.paper import collect

        tty = sys.stderr.isatty()

        def progress(msg):
            print(msg, file=sys.stderr, end="\r" if tty else "\n", flush=True)

        data = collect(_ints(args.N), ["strain", "stress"], _ints(args.inner_N) if args.inner_N else None,
                       progress=progress)
        data["command"] = "dualfem report paper" + (" " + " ".join(argv) if argv else "")
        atomic_write_text(data_path, json.dumps(data, indent=1) + "\n")
        command = data["command"]
    try:
        text = render(data, command)
    except (KeyError, TypeError, IndexError, ValueError, ZeroDivisionError) as exc:   # a record deeper down
        raise InputError(f"--data {str(data_path)!r} is not what 'dualfem report paper' writes: a record lacks or "
                         f"mistypes {describe_exception(exc)}") from None
    atomic_write_text(args.out, text)
    print(f"wrote {args.out}" + ("" if args.render_only else f" and {data_path}"), file=sys.stderr)
    return 0
