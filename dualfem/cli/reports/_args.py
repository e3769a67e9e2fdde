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
