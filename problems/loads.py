"""Traction loads on the top side of the body: the paper's f1, f2, f3 and user-given ones.

A load is a function ``g(x1, x2) -> t2`` giving the vertical traction (units of stress, e.g.
MPa; positive = pulling up) on the top side, or ``(t1, t2)`` for a vector traction. In a TOML
scene file or with ``--set``, ``load`` is ``"f1"``, ``"f2"``, ``"f3"`` or an expression in ``x``
(= x1) and ``y`` (= x2) using numpy functions, e.g. ``load = "-10*sin(pi*x)"``.
"""
from __future__ import annotations

import ast
from collections.abc import Callable

import numpy as np

from dualfem.core.errors import InputError

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


_ALLOWED = {
    "pi": np.pi, "e": np.e, "sin": np.sin, "cos": np.cos, "tan": np.tan, "exp": np.exp,
    "log": np.log, "sqrt": np.sqrt, "abs": np.abs, "where": np.where, "minimum": np.minimum,
    "maximum": np.maximum, "sign": np.sign, "heaviside": np.heaviside, "tanh": np.tanh,
}


#: bounds of a load expression (characters, syntax nodes, nesting depth)
MAX_CHARS = 2000
MAX_NODES = 500
MAX_DEPTH = 50


class _FloatConstants(ast.NodeTransformer):
    """Every integer constant becomes a float: no unbounded big-integer arithmetic."""

    def visit_Constant(self, node: ast.Constant) -> ast.AST:
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise InputError(f"load expression: only arithmetic on numbers is allowed, got the constant {node.value!r}")
        return ast.copy_location(ast.Constant(float(node.value)), node)


def _check_size(tree: ast.AST) -> None:
    nodes, stack = 0, [(tree, 0)]
    while stack:
        node, depth = stack.pop()
        nodes += 1
        if depth > MAX_DEPTH or nodes > MAX_NODES:
            raise InputError(f"load expression is too large: at most {MAX_NODES} terms nested at most "
                             f"{MAX_DEPTH} deep are allowed")
        stack.extend((c, depth + 1) for c in ast.iter_child_nodes(node))


def expression_load(expr: str) -> Traction:
    """A vertical traction given as a numpy expression in ``x`` and ``y``.

    Only arithmetic, comparisons and the functions in ``_ALLOWED`` are accepted. The expression
    is bounded: at most :data:`MAX_CHARS` characters and :data:`MAX_NODES` syntax nodes, nested at
    most :data:`MAX_DEPTH` deep, and every number is a float (so ``9**9**9`` overflows at once
    instead of building a gigantic integer).
    """
    if len(expr) > MAX_CHARS:
        raise InputError(f"load expression is {len(expr)} characters long; at most {MAX_CHARS} are allowed")
    try:
        tree = ast.parse(expr, mode="eval")
    except SyntaxError:
        raise InputError(f"unknown load {expr[:60]!r}: use f1, f2, f3 or a numpy expression in x, y") from None
    except (RecursionError, MemoryError):
        raise InputError(f"load expression is nested too deeply (at most {MAX_DEPTH} levels)") from None
    _check_size(tree)
    tree = ast.fix_missing_locations(_FloatConstants().visit(tree))
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id not in _ALLOWED and node.id not in ("x", "y"):
            raise InputError(f"unknown load {expr!r}: name {node.id!r} is not allowed "
                             f"(use f1, f2, f3 or an expression in x, y with {', '.join(sorted(_ALLOWED))})")
        if isinstance(node, (ast.Attribute, ast.Lambda, ast.Subscript, ast.Starred)):
            raise InputError(f"unknown load {expr!r}: only arithmetic and the functions "
                             f"{', '.join(sorted(_ALLOWED))} are allowed")
    try:
        code = compile(tree, "<load>", "eval")
    except (OverflowError, ValueError, RecursionError, MemoryError) as exc:
        raise InputError(f"load expression cannot be evaluated: {exc}") from None

    def g(x, y):
        val = eval(code, {"__builtins__": {}}, {**_ALLOWED, "x": x, "y": y})  # noqa: S307 - AST-checked
        return np.broadcast_to(np.asarray(val, dtype=float), np.shape(x))

    try:
        with np.errstate(over="raise", invalid="ignore", divide="ignore"):
            test = g(np.linspace(0, 1, 5), np.ones(5))
    except Exception as exc:
        raise InputError(f"load expression {expr!r} cannot be evaluated: {exc}") from None
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
