"""Sweep specs for ``dualfem bench``: read a TOML file, validate every key before anything runs.

Every key and the command line's ``-s``/``-d``/``-r`` selection are documented in docs/bench.md
(a test keeps it complete); the selection itself is :mod:`dualfem.experiments.spec_select`.

A sweep is described by a TOML spec (see ``benchmarks/default.toml``)::

    name = "small"
    repeats = 3            # timed repeats per run (median reported)
    warmup = true          # one untimed run first
    time_limit = 60.0      # seconds per run: passed to the solver's own "time_limit" option and
                           # enforced by a wall-clock guard (the run's process is killed)
    cold_setup = true      # the QP's FactorStore is emptied before every run (store_of(qp).clear(),
                           # dualfem.numerics.linalg): setup is measured with the factorization,
                           # never read from a store; false: every run after the first reuses it
    curves = false         # true: record each run's error along its iterations (curves.csv beside
                           # results.csv, dualfem.experiments.curves); only solvers reporting iterates
    grades = "x"           # what every tier grades: "x" (default: the displacements, energy norm) or
                           # "x,mu" (the multipliers too); dualfem.verify.grading says why
    [tiers]                # tolerance tiers -> each solver's Solver.tolerance_params(tol)
    low = 1e-3
    high = 1e-9
    [reference]            # certified exact solve per scene, cached on disk
    solvers = ["pdas", "clarabel"]  # default: the solvers declaring Solver.reference, by reference_rank
    [[scenes]]             # a grid: every list is a dimension of the cartesian product
    scene = ["f1", "f2"]
    N = [16, 32]
    delta = [1e-3, 1e-9]
    [[solvers]]
    name = "osqp"
    tiers = ["low"]        # default: every tier
    params = {polishing = true}
    grid = {scaling = [0, 10]}
    max = {N = 256}        # only scenes with N <= 256 (min = {...} likewise): the others are not
                           # runs of this solver in the sweep (no row)
    time_limit = 900.0     # this block's own time limit (default: the spec's), e.g. to let a slow
                           # third-party solver show how far it gets on a big scene
    repeats = 1            # this block's own timed repeats (default: the scene block's)
    optional = false       # true: a solver that is not registered is skipped, not an error

Sizes are bounded before anything is expanded (each refusal names the key and the limit): the
file <= MAX_SPEC_BYTES, every ``repeats`` <= MAX_REPEATS, one [[scenes]] grid <= MAX_SCENES
scenes, one solver grid <= MAX_VARIANTS variants, the sweep <= MAX_TASKS runs. A scene whose
estimated peak memory exceeds the memory available to a worker is not run: its runs are skipped
rows with the reason (:func:`dualfem.experiments.tasks.expand_scenes`).
"""
from __future__ import annotations

import itertools
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dualfem.core.errors import InputError
from dualfem.core.solver import reference_solvers
from dualfem.experiments.spec_select import Selection, apply_selection, effective_text
from dualfem.experiments.watchdog import GUARD_FACTOR, GUARD_SLACK
from dualfem.verify.grading import DEFAULT_GRADES, check_grades

SPEC_KEYS = {"name", "description", "repeats", "warmup", "time_limit", "guard_factor", "guard_slack",
             "build_limit", "cold_setup", "curves", "tiers", "grades", "reference", "floor", "scenes", "solvers"}


SCENE_KEYS_RESERVED = {"scene", "repeats", "warmup"}


SOLVER_KEYS = {"name", "tiers", "params", "grid", "max", "min", "optional", "label", "time_limit",
               "repeats"}


REFERENCE_KEYS = {"solvers", "tol", "certify", "time_limit", "params"}


FLOOR_KEYS = {"enabled", "ignore", "repeats", "cholmod", "warmup"}

#: size bounds, checked before anything is expanded, constructed or written (a hostile spec must not
#: hang the command or fill the disk): the spec file's size, timed repeats of a run, scenes of one
#: [[scenes]] grid, variants of one solver grid, and runs of the whole sweep
MAX_SPEC_BYTES = 1_000_000
MAX_REPEATS = 1000
MAX_SCENES = 10_000
MAX_VARIANTS = 1000
MAX_TASKS = 100_000


@dataclass
class Spec:
    """A validated sweep spec."""

    name: str
    path: str
    repeats: int = 3
    warmup: bool = True
    time_limit: float = 60.0
    guard_factor: float = GUARD_FACTOR      # the watchdog's grace, as for solve and compare
    guard_slack: float = GUARD_SLACK
    build_limit: float = 900.0
    cold_setup: bool = True
    curves: bool = False
    tiers: dict[str, float] = field(default_factory=dict)
    grades: str = DEFAULT_GRADES
    reference: dict[str, Any] = field(default_factory=dict)
    floor: dict[str, Any] = field(default_factory=dict)
    scenes: list[dict[str, Any]] = field(default_factory=list)
    solvers: list[dict[str, Any]] = field(default_factory=list)
    text: str = ""

    @property
    def hard_limit(self) -> float:
        """Wall-clock budget of one run with the spec's time limit before its process is killed."""
        return self.guard(self.time_limit)

    def guard(self, time_limit: float) -> float:
        """Wall-clock budget of a phase whose own time limit is ``time_limit`` (seconds)."""
        return time_limit * self.guard_factor + self.guard_slack


def _num(where: str, v: Any, *, lo: float = 0.0, integer: bool = False, allow_zero: bool = False,
         hi: float | None = None) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
            or v < lo or (v == lo and not allow_zero) or (integer and v != int(v)) or (hi is not None and v > hi):
        kind = "an integer" if integer else "a finite number"
        if hi is not None:
            rng = f"in [{lo:g}, {hi:g}]" if allow_zero else f"in ({lo:g}, {hi:g}]"
        else:
            rng = f">= {lo}" if allow_zero else f"> {lo}"
        raise InputError(f"{where} must be {kind} {rng}, got {v!r}")
    return int(v) if integer else float(v)


def _repeats(where: str, v: Any) -> int:
    return int(_num(where, v, lo=1, integer=True, allow_zero=True, hi=MAX_REPEATS))


def _grid_size(where: str, lists: dict[str, Any], limit: int, what: str) -> int:
    """The number of points of a grid (the product of its list lengths), refused above ``limit``
    before any of them is made."""
    size = 1
    for v in lists.values():
        size *= len(v) if isinstance(v, list) else 1
    if size > limit:
        dims = " x ".join(f"{k} ({len(v)})" for k, v in lists.items() if isinstance(v, list) and len(v) > 1)
        raise InputError(f"{where} makes {size:,} {what} ({dims}); the limit is {limit:,}: split the sweep "
                         f"into several specs")
    return size


def _bool(where: str, v: Any) -> bool:
    if not isinstance(v, bool):
        raise InputError(f"{where} must be true or false, got {v!r}")
    return v


def _table(where: str, v: Any, allowed: set[str] | None = None) -> dict:
    if not isinstance(v, dict):
        raise InputError(f"{where} must be a table, got {v!r}")
    if allowed is not None:
        bad = sorted(set(v) - allowed)
        if bad:
            raise InputError(f"unknown key {bad[0]!r} in {where}; allowed: {', '.join(sorted(allowed))}")
    return v


def _as_list(v: Any) -> list:
    return list(v) if isinstance(v, list) else [v]


def load_spec(path: str | Path, selection: Selection | None = None) -> Spec:
    """Read and validate a sweep spec; InputError names the offending key.

    ``selection``: the command line's ``-s``/``-d``/``-r`` (:mod:`dualfem.experiments.spec_select`),
    applied to the parsed file before validation; the spec's ``text`` is then the effective spec."""
    from dualfem.core.io import check_input_path

    path = check_input_path(path, "spec file")
    size = path.stat().st_size
    if size > MAX_SPEC_BYTES:
        raise InputError(f"spec {str(path)!r} is {size:,} bytes; the limit is {MAX_SPEC_BYTES:,} (a sweep spec "
                         f"lists grids, not data)")
    try:
        text = path.read_text(encoding="utf-8")
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"malformed TOML in spec {str(path)!r}: {exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"spec {str(path)!r} is not UTF-8 text") from None
    if selection:
        data = apply_selection(data, selection)
        text = effective_text(data, str(path), selection)
    return parse_spec(data, path=str(path), text=text)


def parse_spec(data: dict, path: str = "<spec>", text: str = "") -> Spec:
    """Validate a spec given as a dict (the parsed TOML)."""
    _table("the spec", data, SPEC_KEYS)
    s = Spec(name=str(data.get("name", Path(path).stem)), path=path, text=text)
    _parse_top(s, data)
    _parse_tiers(s, data)
    _parse_reference(s, data)
    _parse_floor(s, data)
    _parse_scenes(s, data)
    _parse_solvers(s, data)
    _check_task_count(s)
    return s


def _check_task_count(s: Spec) -> None:
    """Runs of the sweep (scenes x solver variants x tiers, an upper bound: before min/max filters and
    duplicates) refused above MAX_TASKS before anything is expanded."""
    scenes = sum(_grid_size("", {k: v for k, v in b.items() if k not in ("repeats", "warmup")}, MAX_SCENES, "")
                 for b in s.scenes)
    runs = sum(scenes * _grid_size("", b["grid"], MAX_VARIANTS, "") * max(len(b["tiers"]), 1) for b in s.solvers)
    if runs > MAX_TASKS:
        raise InputError(f"the spec makes up to {runs:,} runs ({scenes:,} scenes x the solver variants x tiers); "
                         f"the limit is {MAX_TASKS:,}: split the sweep into several specs")


def _parse_top(s: Spec, data: dict) -> None:
    if "repeats" in data:
        s.repeats = _repeats("repeats", data["repeats"])
    if "warmup" in data:
        s.warmup = _bool("warmup", data["warmup"])
    for k in ("time_limit", "guard_factor", "build_limit"):
        if k in data:
            setattr(s, k, _num(k, data[k]))
    if "guard_slack" in data:
        s.guard_slack = _num("guard_slack", data["guard_slack"], allow_zero=True)
    if s.guard_factor < 1:
        raise InputError(f"guard_factor must be >= 1, got {s.guard_factor}")
    if "cold_setup" in data:
        s.cold_setup = _bool("cold_setup", data["cold_setup"])
    if "curves" in data:
        s.curves = _bool("curves", data["curves"])
    if "grades" in data:
        try:
            s.grades = check_grades(data["grades"])
        except ValueError as exc:
            raise InputError(str(exc)) from None


def _parse_tiers(s: Spec, data: dict) -> None:
    tiers = _table("[tiers]", data.get("tiers", {"default": 1e-6}))
    if not tiers:
        raise InputError("[tiers] must name at least one tier, e.g. low = 1e-3")
    s.tiers = {str(k): _num(f"tier {k!r}", v) for k, v in tiers.items()}
    if "any" in s.tiers:
        raise InputError("tier name 'any' is reserved (it marks solvers without tolerance options)")


def _declared_references() -> list[str]:
    """The solvers declaring the reference capability (``Solver.reference``), preferred first."""
    return [n for n, _ in reference_solvers(installed=False)]


def _parse_reference(s: Spec, data: dict) -> None:
    ref = _table("[reference]", data.get("reference", {}), REFERENCE_KEYS)
    s.reference = {
        "solvers": [str(n) for n in _as_list(ref.get("solvers", _declared_references()))],
        "tol": _num("reference.tol", ref.get("tol", 1e-10)),
        "certify": _num("reference.certify", ref.get("certify", 1e-8)),
        "time_limit": _num("reference.time_limit", ref.get("time_limit", max(s.time_limit, 600.0))),
        "params": _table("reference.params", ref.get("params", {})),
    }
    if not s.reference["solvers"]:
        raise InputError("reference.solvers must name at least one exact solver")
    from dualfem.core.registry import solvers

    reg = solvers()
    undeclared = [n for n in s.reference["solvers"] if n in reg and not (getattr(reg[n], "reference", False)
                                                                          and reg[n].exact)]
    if undeclared:      # docs/plugins.md 1.5: a solver is a reference only when its class says so
        raise InputError(f"reference.solvers names {undeclared[0]!r}, which does not declare reference = True "
                         f"(docs/plugins.md 1.5); the reference solvers: {', '.join(_declared_references())}")


def _parse_floor(s: Spec, data: dict) -> None:
    fl = _table("[floor]", data.get("floor", {}), FLOOR_KEYS)
    s.floor = {
        "enabled": _bool("floor.enabled", fl.get("enabled", True)),
        "ignore": [str(k) for k in _as_list(fl.get("ignore", ["load", "load_scale", "delta"]))],
        "repeats": _repeats("floor.repeats", fl.get("repeats", s.repeats)),
        "cholmod": _bool("floor.cholmod", fl.get("cholmod", True)),
        "warmup": _bool("floor.warmup", fl.get("warmup", s.warmup)),
    }


def _parse_scenes(s: Spec, data: dict) -> None:
    scenes = data.get("scenes")
    if not isinstance(scenes, list) or not scenes:
        raise InputError("the spec needs at least one [[scenes]] block")
    for i, blk in enumerate(scenes):
        blk = dict(_table(f"[[scenes]] block {i + 1}", blk))
        if "scene" not in blk:
            raise InputError(f"[[scenes]] block {i + 1} needs scene = \"f1\" (or a list of scenes)")
        if "repeats" in blk:
            _repeats(f"repeats in [[scenes]] block {i + 1}", blk["repeats"])
        if "warmup" in blk:
            _bool(f"warmup in [[scenes]] block {i + 1}", blk["warmup"])
        for k, v in blk.items():
            if isinstance(v, list) and not v:
                raise InputError(f"{k} in [[scenes]] block {i + 1} is an empty list")
        grid = {k: v for k, v in blk.items() if k not in ("repeats", "warmup")}
        _grid_size(f"[[scenes]] block {i + 1}", grid, MAX_SCENES, "scenes")
        s.scenes.append(blk)


def _parse_solvers(s: Spec, data: dict) -> None:
    solvers = data.get("solvers")
    if not isinstance(solvers, list) or not solvers:
        raise InputError("the spec needs at least one [[solvers]] block")
    for i, blk in enumerate(solvers):
        s.solvers.append(_parse_solver_block(s, i, dict(_table(f"[[solvers]] block {i + 1}", blk, SOLVER_KEYS))))


def _parse_solver_block(s: Spec, i: int, blk: dict) -> dict:
    from dualfem.core.registry import solvers as registered

    reg = registered()
    name = blk.get("name")
    if not isinstance(name, str):
        raise InputError(f"[[solvers]] block {i + 1} needs name = \"SOLVER\"")
    optional = _bool(f"optional of solver {name!r}", blk.get("optional", False))
    if name not in reg and not optional:
        raise InputError(f"unknown solver {name!r} in the spec; registered solvers: {', '.join(sorted(reg))} "
                         f"(mark it optional = true to skip it when it is not registered)")
    tiers_ = [str(t) for t in _as_list(blk.get("tiers", list(s.tiers)))]
    for t in tiers_:
        if t not in s.tiers:
            raise InputError(f"solver {name!r} asks for tier {t!r}; tiers of the spec: {', '.join(s.tiers)}")
    params = _table(f"params of solver {name!r}", blk.get("params", {}))
    grid = _table(f"grid of solver {name!r}", blk.get("grid", {}))
    for k, v in grid.items():
        if not isinstance(v, list) or not v:
            raise InputError(f"grid.{k} of solver {name!r} must be a non-empty list")
    _grid_size(f"grid of solver {name!r}", grid, MAX_VARIANTS, "variants")
    for bound in ("max", "min"):
        for k, v in _table(f"{bound} of solver {name!r}", blk.get(bound, {})).items():
            _num(f"{bound}.{k} of solver {name!r}", v, lo=-math.inf)
    if name in reg:  # unknown solver parameters are input errors, found before any run
        for combo in _grid(grid):
            reg[name](**{**params, **combo})
    tl = (_num(f"time_limit of solver {name!r}", blk["time_limit"]) if "time_limit" in blk else None)
    reps = _repeats(f"repeats of solver {name!r}", blk["repeats"]) if "repeats" in blk else None
    return {"name": name, "tiers": tiers_, "params": params, "grid": grid, "max": blk.get("max", {}),
            "min": blk.get("min", {}), "optional": optional, "label": blk.get("label"), "time_limit": tl,
            "repeats": reps}


def _grid(grid: dict[str, list]) -> list[dict[str, Any]]:
    keys = list(grid)
    return [dict(zip(keys, combo)) for combo in itertools.product(*(grid[k] for k in keys))]

