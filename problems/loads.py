"""Traction loads on the top side of the body: the paper's f1, f2, f3 and user-given ones.

A load is a function ``g(x1, x2) -> t2`` giving the vertical traction (units of stress, e.g.
MPa; positive = pulling up) on the top side, or ``(t1, t2)`` for a vector traction. In a TOML
scene file or with ``--set``, ``load`` is ``"f1"``, ``"f2"``, ``"f3"`` or an expression in ``x``
(= x1) and ``y`` (= x2) using numpy functions, e.g. ``load = "-10*sin(pi*x)"`` (vocabulary and
limits: :mod:`dualfem.core.expressions`).
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from dualfem.core.expressions import compile_expression
from dualfem.errors import InputError

Traction = Callable[[np.ndarray, np.ndarray], "np.ndarray | tuple[np.ndarray, np.ndarray]"]


def paper_load(name: str, width: float) -> Traction:
    """The section-5 loads; ``f2`` switches sign at the middle of the top side."""
    if name == "f1":
        return lambda x, y: np.full_like(x, -3.0)
    if name == "f2":
        return lambda x, y: np.where(x < 0.5 * width, -10.0, 10.0)
    if name == "f3":
        return lambda x, y: np.full_like(x, 3.0)
    raise KeyError(name)


def expression_load(expr: str) -> Traction:
    """A vertical traction given as a numpy expression in ``x`` and ``y``.

    Checked and evaluated by the one expression sandbox, :mod:`dualfem.core.expressions` (its size
    limits, vocabulary and float-only evaluation), then sampled on the unit interval: NaN or
    infinite values there are refused (the whole top side is checked after assembly).
    """
    g = compile_expression(expr, parameter="load", variables=("x", "y"),
                           hint="use f1, f2, f3 or a numpy expression in x, y")
    test = g(np.linspace(0, 1, 5), np.ones(5))
    if not np.all(np.isfinite(test)):
        raise InputError(f"load expression {expr!r} gives NaN or infinite values")
    return g


def resolve_load(load, width: float) -> Traction:
    """Turn the ``load`` scene parameter into a traction function."""
    if callable(load):
        return load
    if not isinstance(load, str) or not load.strip():
        raise InputError(f"load must be f1, f2, f3, an expression in x, y or a function, got {load!r}")
    try:
        return paper_load(load.strip(), width)
    except KeyError:
        return expression_load(load.strip())


def check_load_model(problem, pressured: list[bool]) -> None:
    """The load-model trap: a scene without supports and loads of its own (``boundary``, ``body_force``,
    ``remote_stress``) gets the paper's model (bottom clamped, ``load`` on the top side) only when it
    says nothing about loads at all, or names ``load`` itself (a preset such as f2 names it). A scene
    whose defects carry a ``face_pressure`` (``pressured[i]``: defect i has one) and which names no
    ``load`` is refused: it meant the pressure to be its load, not the legacy one on top of it.
    ``problem.given``: the keys the scene gave (:class:`dualfem.problem.Problem`)."""
    if not any(pressured) or "load" in getattr(problem, "given", {"load"}):
        return
    first = pressured.index(True)
    where = "face_pressure" if "face_pressure" in problem.params else f"defects[{first}].face_pressure"
    default = type(problem).defaults.get("load")
    raise InputError(f"{where} is a load of the defects, and the scene names no load model of its body: give "
                     f"its supports and loads ([[boundary]], body_force, remote_stress; e.g. one [[boundary]] table "
                     f"side = 'bottom', support = 'clamp' for the pressure alone: docs/loads.md), or ask for the "
                     f"legacy model explicitly with load = {default!r} (the bottom side clamped, that traction on "
                     f"the top side, and the pressure)")
