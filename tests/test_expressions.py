"""One expression sandbox (dualfem.core.expressions) for every formula a scene may carry.

* the Signorini ``obstacle`` had its own copy of the load sandbox without the size limits:
  ``dualfem solve signorini --set obstacle='9**9**9'`` hung; it is now one clear error line;
* the load sandbox itself let Python integers form from comparisons (``(0<1)+(0<1)`` is 2), so
  ``(nine)**(nine)**(nine)`` built a gigantic integer and hung; numbers are now float64 only;
* every expression-carrying scene key (:data:`EXPRESSION_KEYS`) gets the same limits, in a child
  process with a timeout (a hang fails the test instead of stopping the suite);
* valid expressions give bit for bit the numbers of the former sandboxes;
* no module but dualfem/core/expressions.py parses, compiles or evaluates user text.
"""
from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dualfem.core.errors import InputError
from dualfem.core.expressions import MAX_CHARS, MAX_DEPTH, MAX_NODES, compile_expression, rewrite

REPO = Path(__file__).resolve().parents[1]

#: (scene, key, variables) of every scene key whose value is an expression
EXPRESSION_KEYS = [("f2", "load", ("x", "y")), ("signorini", "obstacle", ("x",))]

_NINE = "+".join(["(0<1)"] * 9)      # 9 as a Python int, were comparisons Python booleans

#: (expression, what the error says): each is refused, quickly, naming the key
REFUSED = [
    ("9**9**9", r"overflows double precision.*\|value\| <= 1\.8e\+308"),
    ("x*1e300*1e300", r"overflows double precision"),
    ("1" + "0" * 400, r"out of range.*\|c\| <= 1\.8e\+308"),
    ("1e400", r"out of range"),
    ("x+" * (MAX_CHARS // 2) + "x", rf"characters long; at most {MAX_CHARS}"),
    ("x+" * MAX_NODES + "x", rf"too large: at most {MAX_NODES} terms nested at most {MAX_DEPTH}"),
    ("sin(" * (MAX_DEPTH + 5) + "x" + ")" * (MAX_DEPTH + 5), r"too large"),
    ("sin(x, x)", r"sin takes exactly 1 positional argument"),
    ("maximum(x, 0, x)", r"maximum takes exactly 2"),
    ("sin(x, out=x)", r"takes exactly 1 positional argument, without keywords"),
    ("(not 0)+(not 0)", r"only arithmetic"),
    ("x is x", r"only arithmetic"),
    ("x and 1", r"only arithmetic"),
    ("[x]", r"only arithmetic"),
    ("(lambda: 1)()", r"only arithmetic"),
    ("x.real", r"only arithmetic"),
    ("'abc'", r"only arithmetic on numbers"),
    ("True", r"only arithmetic on numbers"),
    ("1j", r"only arithmetic on numbers"),
    ("__import__('os').system('true')", r"only arithmetic"),
    ("y_", r"name 'y_' is not allowed"),
    ("10*(x", r"not a valid expression"),
]
#: accepted, and evaluated at once (no Python integer ever forms)
NO_HANG = [f"({_NINE})**({_NINE})**({_NINE})", f"(({_NINE})**({_NINE}))*0+1"]

_CHILD = r"""
import json, sys, time
from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene
scene, key, cases = sys.argv[1], sys.argv[2], json.loads(sys.stdin.read())
out = []
for text in cases:
    t = time.perf_counter()
    try:
        load_scene(scene, {key: text, "N": 8})
        msg = None
    except InputError as exc:
        msg = str(exc)
    out.append([msg, time.perf_counter() - t])
print(json.dumps(out))
"""


def _in_child(scene: str, key: str, cases: list[str]) -> list:
    proc = subprocess.run([sys.executable, "-c", _CHILD, scene, key], input=json.dumps(cases),
                          capture_output=True, text=True, timeout=60, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout)


@pytest.mark.parametrize("scene,key", [(s, k) for s, k, _ in EXPRESSION_KEYS])
def test_cli_huge_exponent_is_one_clear_error_line(scene, key):
    """The reported hang: exit 2 within seconds, one line naming the key and the allowed range."""
    proc = subprocess.run([sys.executable, "-m", "dualfem", "solve", scene, "--set", f"{key}=9**9**9"],
                          capture_output=True, text=True, timeout=30, cwd=REPO)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert re.match(rf"dualfem solve: error: {key} '9\*\*9\*\*9' overflows double precision: its values must "
                    rf"be finite, \|value\| <= 1\.8e\+308$", lines[0]), lines[0]


@pytest.mark.parametrize("scene,key", [(s, k) for s, k, _ in EXPRESSION_KEYS])
def test_every_expression_key_has_the_same_limits(scene, key):
    cases = [text for text, _ in REFUSED] + NO_HANG
    got = _in_child(scene, key, cases)
    for (text, needle), (msg, secs) in zip(REFUSED, got):
        assert msg is not None, f"{key}={text[:40]!r} was accepted"
        assert key in msg and re.search(needle, msg), (text[:40], msg)
        assert secs < 5, (text[:40], secs)
    for text, (msg, secs) in zip(NO_HANG, got[len(REFUSED):]):
        assert msg is None and secs < 5, (text[:40], msg, secs)


def test_the_expression_keys_are_all_the_sandbox_sites():
    """Every call of the sandbox names its key here; no other module parses or evaluates user text."""
    sites = set()
    offenders = []
    for path in [*REPO.glob("dualfem/**/*.py"), *REPO.glob("problems/**/*.py"), *REPO.glob("solvers/**/*.py")]:
        if path == REPO / "dualfem/core/expressions.py":
            continue
        text = path.read_text(encoding="utf-8")
        if path == REPO / "dualfem/experiments/machine.py":   # parses qpsolvers' installed backend modules
            text = text.replace("ast.parse(f.read_text(", "")  # (their imports, for versions), never user text
        sites |= set(re.findall(r"compile_expression\((?:[^()]|\([^()]*\))*?parameter=\"(\w+)\"", text, re.S))
        for pat in (r"(?<![\w.])eval\(", r"(?<![\w.])exec\(", r"(?<![\w.])compile\(", r"\bast\.parse\(",
                    r"\bliteral_eval\("):
            if re.search(pat, text):
                offenders.append(f"{path.relative_to(REPO)}: {pat}")
    assert not offenders, offenders
    assert sites == {k for _, k, _ in EXPRESSION_KEYS}


# ------------------------------------------------- valid expressions: the same numbers as before
_OLD_NAMES = {
    "pi": np.pi, "e": np.e, "sin": np.sin, "cos": np.cos, "tan": np.tan, "exp": np.exp,
    "log": np.log, "sqrt": np.sqrt, "abs": np.abs, "where": np.where, "minimum": np.minimum,
    "maximum": np.maximum, "sign": np.sign, "heaviside": np.heaviside, "tanh": np.tanh,
}


def _old_eval(text: str, float_constants: bool, **arrays) -> np.ndarray:
    """The former sandboxes: Python float constants (loads) or the literals as written (obstacle)."""
    tree = ast.parse(text, mode="eval")
    if float_constants:
        class _F(ast.NodeTransformer):
            def visit_Constant(self, node):
                return ast.copy_location(ast.Constant(float(node.value)), node)
        tree = ast.fix_missing_locations(_F().visit(tree))
    with np.errstate(all="ignore"):
        val = eval(compile(tree, "<old>", "eval"), {"__builtins__": {}}, {**_OLD_NAMES, **arrays})  # noqa: S307
    return np.broadcast_to(np.asarray(val, dtype=float), np.shape(next(iter(arrays.values()))))


VALID = ["-10*cos(2*pi*x) - 2", "0.05*(x-0.5)**2", "where(x < 0.5, -10, 10)", "-3*exp(-((x-0.5)/0.1)**2)",
         "heaviside(x-0.5, 0.5)*3", "sqrt(abs(x-0.3))+maximum(x, 0.2)-minimum(x, 0.7)", "tanh(3*x)/(1+x**3)",
         "sign(x-0.5)*log(1+x)", "2**x", "x % 0.3 + x // 0.3", "7", "0", "-x**0.5*e", "x**-2",
         "where((x > 0.2) & (x < 0.8), 1 if 2 > 1 else 0, -1)", "1/(x+1e-3) + tan(x)", "+x - -x"]


@pytest.mark.parametrize("text", VALID)
def test_valid_expressions_give_the_former_numbers(text):
    x = np.linspace(-0.3, 2.7, 61)
    y = np.linspace(0.5, 1.5, 61)
    load = compile_expression(text, parameter="load", variables=("x", "y"))
    assert np.array_equal(load(x, y), _old_eval(text, True, x=x, y=y), equal_nan=True)
    gap = compile_expression(text, parameter="obstacle", variables=("x",))
    assert np.array_equal(gap(x), _old_eval(text, False, x=x), equal_nan=True)
    assert np.array_equal(x, np.linspace(-0.3, 2.7, 61))       # the arguments are not written to


def test_scenes_with_expressions_build_the_same_qp_as_with_functions():
    """A load / obstacle given as text assembles exactly what the same formula as a Python function does."""
    from dualfem.core.scene import load_scene

    a = load_scene("f2", {"N": 16, "load": "-10*cos(2*pi*x) - 2"}).build()
    b = load_scene("f2", {"N": 16, "load": lambda x, y: -10 * np.cos(2 * np.pi * x) - 2}).build()
    assert np.array_equal(a.F, b.F) and a.F.any()
    a = load_scene("signorini", {"N": 16}).build()
    b = load_scene("signorini", {"N": 16, "obstacle": lambda x: 0.05 * (x - 0.5) ** 2}).build()
    assert np.array_equal(a.F, b.F) and a.F.any()
    assert np.array_equal(a.maps["x_shift"], b.maps["x_shift"])


def test_rewrite_is_checked_and_gives_the_former_strings():
    from dualfem.experiments.stress_grid import _scaled_expression

    assert _scaled_expression("-10*cos(2*pi*x) - 2", 1e-3) == "-10 * cos(2 * pi * (x / 0.001)) - 2"
    assert _scaled_expression("where(x<0.5, -10, 10)*y", 1e3) == "where(x / 1000.0 < 0.5, -10, 10) * (y / 1000.0)"
    assert rewrite("x", {"x": "x / 2.0"}, parameter="load", variables=("x", "y")) == "x / 2.0"
    for bad in ("x.real", "(" * 300 + "x" + ")" * 300, "-" * 300 + "x", "9**9**9" + "+x" * MAX_NODES):
        with pytest.raises(InputError, match="load"):
            _scaled_expression(bad, 1e-3)
