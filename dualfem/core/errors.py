"""User-facing errors.

Every problem with the *input* (a scene parameter, a solver option, a file) raises
:class:`InputError`. Its message names the parameter and the allowed range; the CLI prints it as
one line on stderr and exits with status 2, never with a traceback.
"""
from __future__ import annotations

import math


class InputError(ValueError):
    """Bad input: the message names the parameter and what is allowed."""


class OutputError(InputError):
    """An output file could not be written (disk full, file size limit, permission, ...).

    Raised by the atomic writer, which has removed its temporary file: nothing half-written is
    left. A subclass of InputError so that every command reports it as one line, exit 2.
    """


class MissingDependency(ImportError):
    """An optional dependency is missing; the message says what to install."""


def describe_exception(exc: BaseException) -> str:
    """``"TypeName: message"`` of an exception (``"TypeName"`` alone when the message is empty), never
    raising: a plugin's exception whose ``__str__`` (or whose class's ``__name__``) itself raises is named
    with what can be read, so that reporting a plugin's failure cannot end in a traceback."""
    try:
        name = str(type(exc).__name__)
    except Exception:  # noqa: BLE001 - a hostile metaclass
        name = "exception"
    try:
        msg = str(exc)
    except Exception as inner:  # noqa: BLE001 - a hostile __str__
        try:
            msg = f"<its message cannot be shown: str() raised {type(inner).__name__}>"
        except Exception:  # noqa: BLE001
            msg = "<its message cannot be shown>"
    return f"{name}: {msg}" if msg else name


#: pip distributions whose import name differs from the distribution name
DISTRIBUTIONS = {"skfem": "scikit-fem", "sksparse": "scikit-sparse", "yaml": "pyyaml", "sklearn": "scikit-learn"}


def install_hint(module: str, extra: str | None = None) -> str:
    """The pip command that provides the importable ``module`` (``dualfem[extra]`` when given)."""
    if extra:
        return f"pip install 'dualfem[{extra}]'"
    return f"pip install {DISTRIBUTIONS.get(module.split('.')[0], module.split('.')[0])}"


def missing_module(owner: str, requires: tuple[str, ...], extra: str | None = None) -> str | None:
    """An install hint naming the first of ``requires`` that cannot be imported, else None."""
    import importlib.util

    for mod in requires:
        try:
            found = importlib.util.find_spec(mod) is not None
        except (ImportError, ValueError):   # a parent package missing, or a module blocked in sys.modules
            found = False
        if not found:
            return f"{owner} needs the Python module {mod!r}: {install_hint(mod, extra)}"
    return None


def check_positive(name: str, value, *, allow_zero: bool = False) -> float:
    """Return ``value`` as float if it is finite and > 0 (>= 0 with ``allow_zero``)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        rng = ">= 0" if allow_zero else "> 0"
        raise InputError(f"{name} must be a finite number {rng}, got {value!r}")
    return v


def check_int(name: str, value, lo: int, hi: int | None = None) -> int:
    """Return ``value`` as int if it is an integer in [lo, hi]."""
    if isinstance(value, bool):
        raise InputError(f"{name} must be an integer >= {lo}, got {value!r}")
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an integer >= {lo}, got {value!r}") from None
    if not math.isfinite(f) or f != int(f) or f < lo or (hi is not None and f > hi):
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise InputError(f"{name} must be an integer {rng}, got {value!r}")
    return int(f)


def check_open_interval(name: str, value, lo: float, hi: float) -> float:
    """Return ``value`` as float if it lies in the open interval (lo, hi)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number in ({lo}, {hi}), got {value!r}") from None
    if not math.isfinite(v) or not (lo < v < hi):
        raise InputError(f"{name} must be in the open interval ({lo}, {hi}), got {value!r}")
    return v
