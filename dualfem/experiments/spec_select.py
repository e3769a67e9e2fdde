"""Select and override a sweep spec from the command line, as benchopt does (``-s``, ``-d``, ``-r``).

:func:`parse_pick` is the one parser of the ``NAME[KEY=V,...]`` form: ``bench``'s ``-s``/``-d`` and the
``-s`` of ``solve`` and ``compare`` (:func:`solver_params`) all go through it.

``dualfem bench SPEC -s SOLVER[KEY=V,...] -d SCENE[KEY=V,...] -r REPEATS``:

* ``-s SOLVER[KEY=V,...]`` (repeatable): only the spec's ``[[solvers]]`` blocks of that name (or
  ``label``) run; a solver the spec does not name is added as a new block. Each ``KEY=V`` sets a solver
  parameter in those blocks: a scalar replaces ``params.KEY`` (and drops ``grid.KEY``), a list
  ``KEY=[a,b]`` becomes the grid dimension ``grid.KEY`` (and drops ``params.KEY``).
* ``-d SCENE[KEY=V,...]`` (repeatable): only the ``[[scenes]]`` blocks whose ``scene`` holds SCENE run,
  restricted to SCENE; a scene the spec does not name is added as a new block. Each ``KEY=V`` replaces
  that scene key in those blocks (a list is a grid dimension, as in the spec).
* ``-r REPEATS``: the timed repeats of every run and of the floor (top level and every block).
* ``--tol T``: one tier ``tol = T`` instead of the spec's ``[tiers]`` (every solver block runs it): the
  certified tolerance of every run (:mod:`dualfem.experiments.tolerance`).

Values are TOML values (``1e-9``, ``true``, ``[16, 32]``, ``"f2"``); a bare word that is not one is a
string (``backend=clarabel``). Commas inside brackets or quotes do not split. The result is the
effective spec, written as TOML to the results folder's ``spec.toml`` (rerunning it with ``dualfem
bench DIR/spec.toml`` repeats exactly this sweep); the original file and the options are recorded
in a comment at its top.
"""
from __future__ import annotations

import copy
import re
import tomllib
from dataclasses import dataclass, field
from typing import Any

from dualfem.core.errors import InputError, MissingDependency

#: the longest option value accepted (a selection names solvers and a few keys, not data)
MAX_OPTION_CHARS = 10_000
_NAME = re.compile(r"^[A-Za-z0-9_./:+-]+$")


@dataclass(frozen=True)
class Pick:
    """One ``-s`` or ``-d`` option: a solver or scene name and its overrides, in the order given."""

    name: str
    overrides: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class Selection:
    """The command line's selection: solvers (``-s``), scenes (``-d``) and repeats (``-r``)."""

    solvers: tuple[Pick, ...] = ()
    scenes: tuple[Pick, ...] = ()
    repeats: int | None = None
    options: tuple[str, ...] = field(default=(), compare=False)
    tol: float | None = None

    def __bool__(self) -> bool:
        return bool(self.solvers or self.scenes or self.repeats is not None or self.tol is not None)


def parse_pick(text: str, option: str) -> Pick:
    """``NAME`` or ``NAME[KEY=V,...]`` -> :class:`Pick`; InputError names ``option`` and the syntax."""
    if not isinstance(text, str) or not text.strip() or len(text) > MAX_OPTION_CHARS:
        raise InputError(f"{option} must be NAME or NAME[KEY=VALUE,...] (at most {MAX_OPTION_CHARS:,} characters), "
                         f"got {text!r}"[:300])
    text = text.strip()
    name, bracket, rest = text.partition("[")
    name = name.strip()
    if not _NAME.match(name):
        raise InputError(f"{option} {text!r}: the name must be a solver or scene name (letters, digits, _ . / : + -), "
                         f"got {name!r}")
    if not bracket:
        return Pick(name)
    if not rest.endswith("]"):
        raise InputError(f"{option} {text!r}: unbalanced '[': the overrides must end with ']' (NAME[KEY=VALUE,...])")
    overrides = []
    for item in _split_top(rest[:-1], option, text):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", key):
            raise InputError(f"{option} {text!r}: {item.strip()!r} must be KEY=VALUE with KEY a parameter name")
        if not value.strip():
            raise InputError(f"{option} {text!r}: {key} has no value (KEY=VALUE; a string may be quoted: KEY=\"\")")
        overrides.append((key, _value(value.strip())))
    keys = [k for k, _ in overrides]
    dup = next((k for k in keys if keys.count(k) > 1), None)
    if dup:
        raise InputError(f"{option} {text!r}: the key {dup!r} is given twice")
    return Pick(name, tuple(overrides))


def _split_top(body: str, option: str, text: str) -> list[str]:
    """Split at commas outside brackets and quotes."""
    parts, depth, quote, start = [], 0, "", 0
    for i, ch in enumerate(body):
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
            if depth < 0:
                raise InputError(f"{option} {text!r}: unbalanced ']'")
        elif ch == "," and depth == 0:
            parts.append(body[start:i])
            start = i + 1
    if depth or quote:
        raise InputError(f"{option} {text!r}: unbalanced brackets or quotes")
    parts.append(body[start:])
    if any(not p.strip() for p in parts):
        raise InputError(f"{option} {text!r}: an empty KEY=VALUE item")
    return parts


def _value(raw: str) -> Any:
    """A TOML value, or the bare word as a string."""
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        return raw


def make_selection(solvers: list[str] | None, scenes: list[str] | None, repeats: int | None,
                   options: tuple[str, ...] = (), tol: float | None = None) -> Selection:
    """The selection of the command line's ``-s``/``-d``/``-r`` options, each checked."""
    if repeats is not None:
        from dualfem.experiments.spec import MAX_REPEATS

        if isinstance(repeats, bool) or not isinstance(repeats, int) or not 1 <= repeats <= MAX_REPEATS:
            raise InputError(f"-r/--repeats must be an integer in 1..{MAX_REPEATS}, got {repeats!r}")
    return Selection(tuple(parse_pick(s, "-s/--solver") for s in solvers or ()),
                     tuple(parse_pick(d, "-d/--scene") for d in scenes or ()), repeats, tuple(options), tol)


def solver_params(pick: Pick, option: str = "-s/--solver") -> dict[str, Any]:
    """The overrides of a ``-s`` pick as the parameters of one solver instance (``solve``, ``compare``):
    ``{KEY: value}`` with TOML-typed values, which the solver's constructor validates (its error names
    the allowed keys and ranges). A list value is a grid dimension, which only ``bench`` sweeps: refused."""
    for key, value in pick.overrides:
        if isinstance(value, (list, dict)):
            raise InputError(f"{option} {pick.name}[{key}=...]: a list or table value is a grid of 'dualfem bench'; "
                             f"here give one value per key")
    return dict(pick.overrides)


def apply_selection(data: dict, sel: Selection) -> dict:
    """The spec's parsed TOML with the selection applied (a new dict; ``data`` is not changed)."""
    out = copy.deepcopy(data)
    if sel.solvers:
        out["solvers"] = _select_solvers(out.get("solvers"), sel.solvers)
    if sel.scenes:
        out["scenes"] = _select_scenes(out.get("scenes"), sel.scenes)
    if sel.repeats is not None:
        out["repeats"] = sel.repeats
        for blk in [*_blocks(out.get("scenes")), *_blocks(out.get("solvers"))]:
            if "repeats" in blk:
                blk["repeats"] = sel.repeats
        if isinstance(out.get("floor"), dict) and "repeats" in out["floor"]:
            out["floor"]["repeats"] = sel.repeats
    if sel.tol is not None:
        out["tiers"] = {"tol": sel.tol}
        for blk in _blocks(out.get("solvers")):
            blk.pop("tiers", None)
    return out


def _blocks(v: Any) -> list[dict]:
    return [b for b in v if isinstance(b, dict)] if isinstance(v, list) else []


def _select_solvers(blocks: Any, picks: tuple[Pick, ...]) -> list[dict]:
    chosen = []
    for pick in picks:
        found = [copy.deepcopy(b) for b in _blocks(blocks) if pick.name in (b.get("name"), b.get("label"))]
        for blk in found or [{"name": pick.name}]:
            params = dict(blk.get("params", {})) if isinstance(blk.get("params"), dict) else {}
            grid = dict(blk.get("grid", {})) if isinstance(blk.get("grid"), dict) else {}
            for key, value in pick.overrides:
                if isinstance(value, list):
                    grid[key] = value
                    params.pop(key, None)
                else:
                    params[key] = value
                    grid.pop(key, None)
            for key, table in (("params", params), ("grid", grid)):
                if table:
                    blk[key] = table
                else:
                    blk.pop(key, None)
            chosen.append(blk)
    return _unique(chosen)


def _select_scenes(blocks: Any, picks: tuple[Pick, ...]) -> list[dict]:
    chosen = []
    for pick in picks:
        found = []
        for b in _blocks(blocks):
            names = b.get("scene") if isinstance(b.get("scene"), list) else [b.get("scene")]
            if pick.name in names:
                found.append({**copy.deepcopy(b), "scene": pick.name})
        for blk in found or [{"scene": pick.name}]:
            for key, value in pick.overrides:
                if key == "scene":
                    raise InputError(f"-d/--scene {pick.name}[...]: give the scene as the name, not as scene=...")
                blk[key] = value
            chosen.append(blk)
    return _unique(chosen)


def _unique(blocks: list[dict]) -> list[dict]:
    """The blocks without repeats (two spec blocks restricted to one scene can become the same)."""
    out: list[dict] = []
    for b in blocks:
        if b not in out:
            out.append(b)
    return out


def effective_text(data: dict, source: str, sel: Selection) -> str:
    """The effective spec as TOML, headed by a comment naming the file and the options it came from."""
    try:
        import tomli_w
    except ImportError:
        raise MissingDependency("dualfem bench -s/-d/-r writes the effective spec with tomli-w: "
                                "pip install tomli-w (a dependency of dualfem: reinstall it)") from None
    opts = " ".join(sel.options)
    head = f"# the spec {source} with the command-line selection: {opts}\n".replace("\n", " ").rstrip() + "\n"
    return head + tomli_w.dumps(data)
