"""Every solver parameter is validated before the library sees it (issue 14, item 5).

Each built-in solver declares the allowed values of every parameter (``Solver.ranges`` plus the
shared vocabulary's ``COMMON_RANGES``); ``Solver.__init__`` and the runner check them. Here every
registered built-in solver is given values just outside each declared range, non-finite numbers,
booleans for numbers, numbers for booleans and unknown choices, in Python and on the command line:
each is refused with an InputError naming the parameter and the allowed range.

The range test is table-driven: one item per solver loops over every declared parameter and every
out-of-range value of :func:`cases` and lists every failure at once (the same checks as one item per
value, 1558 of them before, in 34 items).
"""
from __future__ import annotations

import math

import pytest

from dualfem.cli.main import main
from dualfem.core.errors import InputError
from dualfem.core.registry import solvers
from dualfem.core.solver import COMMON_RANGES, describe_range, interval

BUILTIN = sorted(n for n, c in solvers().items() if c.__module__.startswith("dualfem.solvers."))

#: parameters whose allowed values depend on what is installed (checked by validate()), with a bad value
DYNAMIC = {"factor": "no_such_backend", "solver": "NO_SUCH_BACKEND", "direct_solve_method": "no_such_method"}


def bad_values(spec, default) -> list:
    """Values outside ``spec`` (see Solver.ranges) for a parameter whose default is ``default``."""
    if spec is bool:
        return [2, 0.5, "maybe", None]
    if isinstance(spec, tuple):
        return ["no_such_choice", 3, True]
    integer = isinstance(default, int) and not isinstance(default, bool)
    lo, hi, lo_closed, hi_closed = interval(spec)
    out: list = [math.nan, -math.inf, math.inf, True, "abc", None]
    step = 1 if integer else 1e-9 * max(1.0, abs(lo))
    if math.isfinite(lo):
        out.append(lo - step if lo_closed else lo)
    if math.isfinite(hi):
        out.append(hi + (1 if integer else 1e-9 * max(1.0, abs(hi))) if hi_closed else hi)
    if integer:
        out.append(default + 0.5)
    return out


def cases(name: str) -> list[tuple[str, object, object]]:
    """(parameter, bad value, spec) of every out-of-range value of every declared parameter of ``name``:
    the values of :func:`bad_values` for a declared range, the :data:`DYNAMIC` value for a parameter
    checked against what is installed (only when the solver itself is installed)."""
    cls = solvers()[name]
    ranges = cls.param_ranges()
    out = []
    for key, default in cls.defaults.items():
        spec = ranges.get(key)
        if spec is None:
            if key in DYNAMIC and cls.missing() is None:
                out.append((key, DYNAMIC[key], None))
            continue
        out += [(key, v, spec) for v in bad_values(spec, default)]
    return out


def refusal_problem(name: str, key: str, value, spec) -> str | None:
    """None if ``solvers()[name](key=value)`` is refused with an InputError naming the parameter, the
    solver and (for a non-string value of a declared range) the allowed range; else what went wrong."""
    cls = solvers()[name]
    try:
        cls(**{key: value})
    except InputError as exc:
        msg = str(exc)
    except Exception as exc:  # noqa: BLE001 - any other exception is a failure of the check, reported
        return f"{type(exc).__name__} instead of InputError: {exc}"
    else:
        return "accepted"
    if f"'{key}'" not in msg or f"'{name}'" not in msg:
        return f"message does not name '{key}' and '{name}': {msg}"
    if spec is not None and not isinstance(value, str) and value is not None:
        integer = isinstance(cls.defaults[key], int) and not isinstance(cls.defaults[key], bool)
        if describe_range(spec, integer) not in msg:
            return f"message does not state the range {describe_range(spec, integer)!r}: {msg}"
    return None


@pytest.mark.parametrize("name", BUILTIN)
def test_every_parameter_declares_its_range(name):
    cls = solvers()[name]
    declared = cls.param_ranges()
    assert set(declared) == set(cls.defaults), f"{name}: no declared range for {set(cls.defaults) - set(declared)}"
    for key, spec in declared.items():
        assert spec is not None or key in DYNAMIC, f"{name}.{key}: spec None but no bad value in DYNAMIC"
        if isinstance(spec, str):
            interval(spec)                                   # well formed


@pytest.mark.parametrize("name", BUILTIN)
def test_defaults_lie_in_their_ranges(name):
    cls = solvers()[name]
    s = cls()                                                # raises if a default is outside its range
    assert s.params == cls.defaults


@pytest.mark.parametrize("name", BUILTIN)
def test_out_of_range_values_are_refused(name):
    """Table-driven: every declared parameter of the solver, every out-of-range value of its range
    (:func:`cases`), each refused as :func:`refusal_problem` demands; all failures listed at once."""
    todo = cases(name)
    assert todo, f"{name}: no out-of-range value to try"
    failures = [f"{name}.{key}={value!r}: {why}" for key, value, spec in todo
                if (why := refusal_problem(name, key, value, spec)) is not None]
    assert not failures, f"{len(failures)} of {len(todo)} bad values not refused properly:\n" + "\n".join(failures)


def test_the_range_table_covers_every_declared_parameter():
    """The table of :func:`cases` has values for every declared range of every built-in solver, and the
    check of :func:`refusal_problem` fails when a value is accepted or the message misses the range."""
    for name in BUILTIN:
        cls = solvers()[name]
        keys = {k for k, _, _ in cases(name)}
        expected = {k for k, spec in cls.param_ranges().items() if spec is not None}
        expected |= {k for k in cls.defaults if k in DYNAMIC and cls.missing() is None}
        assert keys == expected, (name, expected - keys)
    assert len([c for n in BUILTIN for c in cases(n)]) >= 1500          # the 1558 items of the parametrized form
    # the check itself can fail: a value inside the range is accepted, and reported
    assert refusal_problem("pdas", "tol", 1e-6, "(0, inf)") == "accepted"


def test_the_shared_vocabulary_is_checked_for_every_solver():
    assert COMMON_RANGES == {"tol": "(0, inf)", "max_iter": "[1, inf)", "time_limit": "(0, inf)", "verbose": bool}
    for name in BUILTIN:
        assert set(COMMON_RANGES) <= set(solvers()[name].param_ranges()), name


def test_the_runner_checks_parameters_changed_after_construction():
    from dualfem.core.scene import load_scene
    from dualfem.experiments.runner import run

    s = solvers()["pdas"]()
    s.params["tol"] = -1.0
    with pytest.raises(InputError, match="'tol'"):
        run(s, load_scene("f2", {"N": 8}).build())


SHARED_BAD = ["tol=-1", "max_iter=0", "time_limit=0", "verbose=maybe", "tol=true"]


@pytest.mark.parametrize("param", SHARED_BAD)
def test_cli_refuses_bad_shared_parameters(param, capsys):
    """Every built-in solver on the command line: exit 2, one stderr line naming the parameter."""
    key = param.split("=")[0]
    failures = []
    for name in BUILTIN:
        rc = main(["solve", "f2", "--set", "N=8", "--solver", name, "-p", param])
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if ln.strip()]
        if not (rc == 2 and len(lines) == 1 and lines[0].startswith("dualfem solve: error: parameter ")
                and f"'{key}'" in lines[0]):
            failures.append(f"{name} -p {param}: exit {rc}, stderr {err!r}")
    assert not failures, f"{len(failures)} of {len(BUILTIN)} solvers:\n" + "\n".join(failures)


def test_list_json_shows_the_allowed_values(capsys):
    import json

    assert main(["list", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)["solvers"]
    assert d["uzawa"]["allowed"]["tol_mode"] == "one of relative, absolute"
    assert d["osqp"]["allowed"]["scaling"] == "an integer in [0, 100]"
    assert d["pdas"]["allowed"]["time_limit"] == "a finite number > 0"


def test_a_third_party_plugin_keeps_its_own_meanings_and_gets_the_shared_checks():
    """A plugin written before ``ranges`` (time_limit = 0 meaning 'none', verbose = 0) still loads;
    the shared ranges apply to the parameters whose defaults lie in them."""
    from dualfem.core.solver import Solver

    class OldPlugin(Solver):
        name = "test_old_plugin"
        defaults = {"tol": 1e-6, "max_iter": 100, "time_limit": 0.0, "verbose": 0}

    assert set(OldPlugin.param_ranges()) == {"tol", "max_iter"}
    assert OldPlugin().params["time_limit"] == 0.0
    with pytest.raises(InputError, match="'tol'.*> 0"):
        OldPlugin(tol=-1)
    with pytest.raises(InputError, match="'max_iter'.*integer >= 1"):
        OldPlugin(max_iter=0)
