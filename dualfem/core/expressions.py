"""The one sandbox for the formulas a scene may carry (``load`` in x, y; ``obstacle`` in x; ...).

Every place that evaluates or rewrites a user-given expression goes through this module:
:func:`compile_expression` (a checked, float-only function of the variables) and :func:`rewrite`
(substitute the variables, e.g. the stress grid's change of length unit). Nothing else in dualfem
calls ``eval`` or ``compile`` on user text.

Limits, checked before anything is evaluated (an InputError names the scene key and the limit):

* size: at most :data:`MAX_CHARS` characters and :data:`MAX_NODES` syntax nodes, nested at most
  :data:`MAX_DEPTH` deep;
* syntax: numbers, the variables, ``pi``, ``e``, ``+ - * / // % **``, unary ``+ -``, comparisons
  (``< <= > >= == !=``), ``& | ^ ~`` (to combine comparisons), ``a if c else b`` and calls of
  the functions of :data:`FUNCTIONS` with their number of positional arguments (no keywords:
  no ``out=``); no attributes, subscripts, lambdas, comprehensions, ``and``/``or``/``not``,
  ``is``/``in`` or strings;
* numbers: every literal is a finite float, ``|c| <=`` :data:`MAX_NUMBER`, and it is evaluated as a
  numpy float64, so no Python integer ever forms: ``9**9**9`` overflows at once (and is refused
  by the probe below) instead of building a gigantic integer, and a comparison gives numpy
  booleans, not Python ones;
* values: a probe evaluation at :data:`PROBE` points of every variable must not overflow double
  precision (``|value| <=`` :data:`MAX_NUMBER`) nor raise.

The site keeps its domain checks (a load finite on the top side, a gap >= 0 on the bottom side).
"""
from __future__ import annotations

import ast
import sys
from collections.abc import Callable, Sequence

import numpy as np

from dualfem.core.errors import InputError

#: bounds of an expression (characters, syntax nodes, nesting depth)
MAX_CHARS = 2000
MAX_NODES = 500
MAX_DEPTH = 50
#: the largest magnitude of a number literal or a value (that of a double)
MAX_NUMBER = sys.float_info.max
#: points (in each variable) of the probe evaluation
PROBE = np.linspace(0.0, 1.0, 5)

#: the callable names and how many positional arguments each takes
FUNCTIONS: dict[str, tuple[Callable, int]] = {
    "sin": (np.sin, 1), "cos": (np.cos, 1), "tan": (np.tan, 1), "tanh": (np.tanh, 1),
    "exp": (np.exp, 1), "log": (np.log, 1), "sqrt": (np.sqrt, 1), "abs": (np.abs, 1),
    "sign": (np.sign, 1), "minimum": (np.minimum, 2), "maximum": (np.maximum, 2),
    "heaviside": (np.heaviside, 2), "where": (np.where, 3),
}
#: the named constants
CONSTANTS: dict[str, float] = {"pi": float(np.pi), "e": float(np.e)}

_BINOPS = (ast.Add, ast.Sub, ast.Mult, ast.Div, ast.FloorDiv, ast.Mod, ast.Pow,
           ast.BitAnd, ast.BitOr, ast.BitXor)
_UNARY = (ast.UAdd, ast.USub, ast.Invert)
_COMPARE = (ast.Lt, ast.LtE, ast.Gt, ast.GtE, ast.Eq, ast.NotEq)
_STRUCTURE = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Compare, ast.Call, ast.Name, ast.Constant,
              ast.IfExp, ast.Load, *_BINOPS, *_UNARY, *_COMPARE)


def allowed(variables: Sequence[str]) -> str:
    """The vocabulary of an expression in ``variables``, for error messages."""
    funcs = ", ".join(f"{n}({', '.join('abc'[:k])})" if k > 1 else n for n, (_, k) in sorted(FUNCTIONS.items()))
    return (f"numbers, {', '.join(variables)}, pi, e, + - * / // % **, comparisons, & | ~, "
            f"'a if c else b' and the functions {funcs}")


def _check_size(tree: ast.AST, parameter: str) -> None:
    nodes, stack = 0, [(tree, 0)]
    while stack:
        node, depth = stack.pop()
        nodes += 1
        if depth > MAX_DEPTH or nodes > MAX_NODES:
            raise InputError(f"{parameter} expression is too large: at most {MAX_NODES} terms nested at most "
                             f"{MAX_DEPTH} deep are allowed")
        stack.extend((c, depth + 1) for c in ast.iter_child_nodes(node))


def _number(node: ast.Constant, text: str, parameter: str) -> float:
    v = node.value
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(f"{parameter} {text!r}: only arithmetic on numbers is allowed, got the constant {v!r}")
    try:
        f = float(v)
    except OverflowError:
        f = float("inf")
    if not abs(f) <= MAX_NUMBER:
        lit = ast.get_source_segment(text, node) or str(v)
        raise InputError(f"{parameter} {text[:60]!r}: the number {lit[:30]} is out of range; numbers must be "
                         f"finite, |c| <= {MAX_NUMBER:.1e}")
    return f


def parse(text: str, *, parameter: str, variables: Sequence[str], hint: str = "") -> ast.Expression:
    """The syntax tree of ``text`` after every check of the module docstring but the probe.

    ``parameter`` (the scene key) and ``hint`` (what the key accepts) go into the error messages.
    """
    hint = hint or f"use an expression in {', '.join(variables)}"
    if not isinstance(text, str):
        raise InputError(f"{parameter} must be an expression in {', '.join(variables)}, got {text!r}")
    if len(text) > MAX_CHARS:
        raise InputError(f"{parameter} expression is {len(text)} characters long; at most {MAX_CHARS} are allowed")
    text = text.strip()
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError:
        raise InputError(f"unknown {parameter} {text[:60]!r}: not a valid expression ({hint})") from None
    except (RecursionError, MemoryError):
        raise InputError(f"{parameter} expression is nested too deeply (at most {MAX_DEPTH} levels)") from None
    _check_size(tree, parameter)
    names = set(variables) | set(CONSTANTS)
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id not in names and node.id not in FUNCTIONS:
            raise InputError(f"unknown {parameter} {text!r}: name {node.id!r} is not allowed "
                             f"({hint}; allowed: {allowed(variables)})")
        if not isinstance(node, _STRUCTURE):
            raise InputError(f"unknown {parameter} {text!r}: only arithmetic and the functions "
                             f"{', '.join(sorted(FUNCTIONS))} are allowed, not {type(node).__name__} "
                             f"({hint}; allowed: {allowed(variables)})")
        if isinstance(node, ast.Constant):
            _number(node, text, parameter)
        if isinstance(node, ast.Call):
            func = node.func
            if not (isinstance(func, ast.Name) and func.id in FUNCTIONS):
                raise InputError(f"unknown {parameter} {text!r}: only arithmetic and the functions "
                                 f"{', '.join(sorted(FUNCTIONS))} are allowed ({hint})")
            k = FUNCTIONS[func.id][1]
            if node.keywords or len(node.args) != k or any(isinstance(a, ast.Starred) for a in node.args):
                raise InputError(f"{parameter} {text!r}: {func.id} takes exactly {k} positional "
                                 f"argument{'s' if k > 1 else ''}, without keywords")
    return tree


class _Float64Constants(ast.NodeTransformer):
    """Each number literal becomes a name bound to a numpy float64 (no Python int, no folding)."""

    def __init__(self, text: str, parameter: str) -> None:
        self.values: dict[str, np.float64] = {}
        self.text, self.parameter = text, parameter

    def visit_Constant(self, node: ast.Constant) -> ast.AST:
        name = f"_c{len(self.values)}"
        self.values[name] = np.float64(_number(node, self.text, self.parameter))
        return ast.copy_location(ast.Name(id=name, ctx=ast.Load()), node)


class Expression:
    """A checked expression: call it with one array per variable (in the order of ``variables``).

    Returns a float ndarray of the broadcast shape of the arguments (a new array; floating-point
    warnings are silenced: the caller checks finiteness where it matters).
    """

    def __init__(self, text: str, *, parameter: str, variables: Sequence[str], hint: str = "") -> None:
        self.text, self.parameter, self.variables = text.strip(), parameter, tuple(variables)
        tree = parse(self.text, parameter=parameter, variables=self.variables, hint=hint)
        sub = _Float64Constants(self.text, parameter)
        tree = ast.fix_missing_locations(sub.visit(tree))
        try:
            self._code = compile(tree, f"<{parameter}>", "eval")
        except (OverflowError, ValueError, RecursionError, MemoryError) as exc:
            raise InputError(f"{parameter} {self.text!r} cannot be evaluated: {exc}") from None
        self._names: dict[str, object] = {**CONSTANTS, **{n: f for n, (f, _) in FUNCTIONS.items()}, **sub.values}

    def evaluate(self, *arrays) -> np.ndarray:
        """The values at ``arrays`` (one per variable), with numpy's error state as the caller set it."""
        if len(arrays) != len(self.variables):
            raise TypeError(f"{self.parameter}: expected {len(self.variables)} arrays ({', '.join(self.variables)})")
        env = {**self._names, **dict(zip(self.variables, arrays))}
        val = eval(self._code, {"__builtins__": {}}, env)  # noqa: S307 - checked by parse(), float64 only
        shape = np.broadcast_shapes(*(np.shape(a) for a in arrays))
        return np.broadcast_to(np.asarray(val, dtype=float), shape).copy()

    def __call__(self, *arrays) -> np.ndarray:
        with np.errstate(all="ignore"):
            return self.evaluate(*arrays)

    def probe(self) -> None:
        """Evaluate at :data:`PROBE` (every variable); InputError on an overflow or an exception."""
        pts = [PROBE] + [np.ones_like(PROBE)] * (len(self.variables) - 1)
        try:
            with np.errstate(over="raise", invalid="ignore", divide="ignore", under="ignore"):
                self.evaluate(*pts)
        except FloatingPointError:
            raise InputError(f"{self.parameter} {self.text!r} overflows double precision: its values must be "
                             f"finite, |value| <= {MAX_NUMBER:.1e}") from None
        except Exception as exc:
            raise InputError(f"{self.parameter} {self.text!r} cannot be evaluated: {type(exc).__name__}: "
                             f"{exc}") from None

    def __repr__(self) -> str:
        return f"Expression({self.text!r}, parameter={self.parameter!r}, variables={self.variables!r})"


def compile_expression(text: str, *, parameter: str, variables: Sequence[str], hint: str = "") -> Expression:
    """A checked, probed :class:`Expression` of ``text`` in ``variables`` for the scene key ``parameter``."""
    expr = Expression(text, parameter=parameter, variables=variables, hint=hint)
    expr.probe()
    return expr


def rewrite(text: str, substitutions: dict[str, str], *, parameter: str, variables: Sequence[str],
            hint: str = "") -> str:
    """``text`` (checked like :func:`parse`) with each variable replaced by an expression of it.

    ``rewrite("-10*x", {"x": "x / 1000.0"}, ...)`` is ``'-10 * (x / 1000.0)'``; the result is
    itself checked when it is compiled.
    """
    tree = parse(text, parameter=parameter, variables=variables, hint=hint)
    subs = {k: ast.parse(v, mode="eval").body for k, v in substitutions.items()}

    class _Sub(ast.NodeTransformer):
        def visit_Name(self, node: ast.Name) -> ast.AST:
            return subs[node.id] if node.id in subs else node

    return ast.unparse(ast.fix_missing_locations(_Sub().visit(tree)))
