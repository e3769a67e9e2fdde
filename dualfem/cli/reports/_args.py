"""Argument helpers shared by the report commands."""
from __future__ import annotations

import math
import sys

from dualfem.core.errors import InputError


def strip_dashes(argv: list[str]) -> list[str]:
    """``dualfem report KIND -- --opt ...`` (older dispatchers needed the ``--``): drop a leading ``--``."""
    argv = list(argv)
    return argv[1:] if argv[:1] == ["--"] else argv


def floats(text: str, name: str) -> list[float]:
    """A comma-separated list of positive finite numbers (``--deltas``)."""
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{name} must be a comma-separated list of numbers, got {text!r}") from None
    if not vals or any(not (math.isfinite(v) and v > 0) for v in vals):
        raise InputError(f"{name} must be positive numbers, got {text!r}")
    return vals


def ints(text: str, name: str) -> list[int]:
    """A comma-separated list of integers >= 4 (mesh sizes)."""
    vals = floats(text, name)
    if any(v != int(v) or v < 4 for v in vals):
        raise InputError(f"{name} must be integers >= 4, got {text!r}")
    return [int(v) for v in vals]


def progress(msg: str) -> None:
    """One progress line on stderr."""
    print(msg, file=sys.stderr, flush=True)


def add_target_args(p) -> None:
    """``--ours``, ``--shift``, ``--error``, ``--targets``: the performance-target options of ``report bench``
    and ``report html``."""
    from dualfem.reports._bench_util import OURS

    p.add_argument("--ours", default=",".join(OURS), help="comma-separated solvers checked against the targets")
    p.add_argument("--shift", type=float, default=10.0, help="shift of the geometric mean in seconds (10)")
    p.add_argument("--error", type=float, default=1e-8, help="equal-error level of the targets (1e-8)")
    p.add_argument("--targets", action="store_true",
                   help="add dualfem's own performance-target checklist (--ours against the floor and the "
                        "competitors); off by default: it is the project's benchmark, not the user's")


def target_args(a) -> dict:
    """The checked target options as keyword arguments: ``ours`` (list), ``shift``, ``err_target``,
    ``show_targets`` (whether the target checklist is shown)."""
    if not (a.shift >= 0 and math.isfinite(a.shift)):
        raise InputError(f"--shift must be a finite number >= 0, got {a.shift}")
    if not (a.error > 0 and math.isfinite(a.error)):
        raise InputError(f"--error must be a finite number > 0, got {a.error}")
    return {"ours": [s for s in a.ours.split(",") if s], "shift": a.shift, "err_target": a.error,
            "show_targets": bool(a.targets)}
