"""The supports-and-loads scene keys (``[[boundary]]``, ``body_force``, ``remote_stress``, a defect's
``face_pressure``) parsed and checked into frozen, typed objects; the box's sides. The meaning of every
key, its units and signs: :mod:`dualfem.problems._boundary` and docs/loads.md (this module is its
parsing half; import both through ``_boundary``).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dualfem.core.expressions import Expression, compile_expression
from dualfem.errors import InputError

SIDES: dict[int, tuple[str, ...]] = {2: ("left", "right", "bottom", "top"),
                                     3: ("left", "right", "front", "back", "bottom", "top")}
SUPPORTS = ("clamp", "roller", "free")
#: the scene keys of this module (``face_pressure`` is a key of each defect)
KEYS = ("boundary", "body_force", "remote_stress")
TABLE_KEYS = ("side", "support", "traction")
VARIABLES: dict[int, tuple[str, ...]] = {2: ("x", "y"), 3: ("x", "y", "z")}


def side_axis(side: str, dim: int) -> tuple[int, bool]:
    """(the coordinate axis normal to ``side``, whether the side is at the box's far end)."""
    k = SIDES[dim].index(side)
    return k // 2, bool(k % 2)


def outward_normal(side: str, dim: int) -> np.ndarray:
    """The outward unit normal (dim,) of ``side`` in the reference frame."""
    axis, far = side_axis(side, dim)
    n = np.zeros(dim)
    n[axis] = 1.0 if far else -1.0
    return n


def box_lengths(params: dict, dim: int) -> tuple[float, ...]:
    """The box's lengths along x, y (, z): (width, height) in 2D, (width, depth, height) in 3D."""
    return (float(params["width"]), float(params["height"])) if dim == 2 else \
        (float(params["width"]), float(params["depth"]), float(params["height"]))


# --------------------------------------------------------------------------- the typed keys
@dataclass(frozen=True)
class Field:
    """A vector (or scalar: one component) field given by numbers and/or expressions in x, y (, z).

    ``values``: the scene's values (floats, or expression texts), which define equality; ``key``: the
    scene key in messages. Call it with coordinates X (dim, ...) to get (ncomp, ...).
    """

    key: str
    values: tuple[float | str, ...]
    dim: int
    compiled: tuple[Expression | float, ...] = field(compare=False, repr=False, default=())

    @property
    def constant(self) -> bool:
        return all(not isinstance(v, str) for v in self.values)

    def __call__(self, X: np.ndarray) -> np.ndarray:
        shape = X.shape[1:]
        out = np.empty((len(self.values),) + shape)
        for c, g in enumerate(self.compiled):
            out[c] = g(*X) if isinstance(g, Expression) else g
        return out

    def label(self) -> list:
        return list(self.values)


@dataclass(frozen=True)
class Side:
    """One ``[[boundary]]`` table: the side, its support and its traction (None: none)."""

    side: str
    support: str = "free"
    traction: Field | None = None


@dataclass(frozen=True)
class LoadSpec:
    """The supports and loads of a scene (see the module docstring); ``stress`` as nested tuples."""

    dim: int
    box: tuple[float, ...]
    sides: tuple[Side, ...] = ()
    body_force: Field | None = None
    remote_stress: tuple[tuple[float, ...], ...] | None = None

    def side(self, name: str) -> Side:
        """The table of side ``name`` (a free, unloaded one if not listed)."""
        for s in self.sides:
            if s.side == name:
                return s
        return Side(name)

    @property
    def has_support(self) -> bool:
        return any(s.support != "free" for s in self.sides)

    @property
    def stress(self) -> np.ndarray | None:
        return None if self.remote_stress is None else np.array(self.remote_stress, dtype=float)

    def label(self) -> str:
        """A compact text of the keys (for ``QP.params`` and cache keys)."""
        parts = [f"{{side: {s.side}, support: {s.support}"
                 + (f", traction: {s.traction.label()}" if s.traction else "") + "}" for s in self.sides]
        out = f"boundary: [{', '.join(parts)}]"
        if self.body_force is not None:
            out += f", body_force: {self.body_force.label()}"
        if self.remote_stress is not None:
            out += f", remote_stress: {[list(r) for r in self.remote_stress]}"
        return out


# --------------------------------------------------------------------------- parsing
def _json(key: str, value: Any, form: str) -> Any:
    """A TOML value as is; a string (``--set``) read as JSON (a list or table), else left a string."""
    if isinstance(value, str):
        text = value.strip()
        if text[:1] in "[{":
            try:
                return json.loads(text)
            except ValueError:
                raise InputError(f"{key} must be {form} (from --set: JSON), got {value!r}") from None
    return value


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def _sample(box: tuple[float, ...], side: str | None, k: int = 7) -> np.ndarray:
    """Points (dim, k^(dim-1 or dim)) on a side of the box (or in the whole box when side is None)."""
    dim = len(box)
    axes = [np.linspace(0.0, L, k) for L in box]
    if side is not None:
        axis, far = side_axis(side, dim)
        axes[axis] = np.array([box[axis] if far else 0.0])
    grid = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grid])


def parse_field(value: Any, key: str, dim: int, ncomp: int, box: tuple[float, ...], side: str | None) -> Field:
    """A vector of ``ncomp`` numbers or expression strings in x, y (, z) (a scalar when ncomp = 1 may be
    given bare); each expression is checked by the sandbox and must be finite on ``side`` (the whole
    box when None). InputError naming ``key``."""
    names = ", ".join(VARIABLES[dim])
    form = (f"a vector of {ncomp} numbers or expressions in {names}" if ncomp > 1 else
            f"a number or an expression in {names}")
    v = _json(key, value, form)
    if ncomp == 1 and (_is_number(v) or isinstance(v, str)):
        v = [v]
    if not isinstance(v, (list, tuple)) or len(v) != ncomp:
        got = f" ({len(v)} components)" if isinstance(v, (list, tuple)) else ""
        raise InputError(f"{key} must be {form}, got {value!r}{got}")
    values, compiled = [], []
    where = "in the body" if side is None else f"on the {side} side"
    for c, item in enumerate(v):
        ckey = key if ncomp == 1 else f"{key}[{c}]"
        if _is_number(item):
            f = float(item)
            if not math.isfinite(f):
                raise InputError(f"{ckey} must be finite, got {item!r}")
            values.append(f)
            compiled.append(f)
        elif isinstance(item, str) and item.strip():
            expr = compile_expression(item, parameter=ckey, variables=VARIABLES[dim],
                                      hint=f"give {form}")
            if not np.all(np.isfinite(expr(*_sample(box, side)))):
                raise InputError(f"{ckey} = {item!r} gives NaN or infinite values {where}; it must be finite there")
            values.append(expr.text)
            compiled.append(expr)
        else:
            raise InputError(f"{ckey} must be a number or an expression in {names} (a string), got {item!r}")
    return Field(key, tuple(values), dim, tuple(compiled))


def parse_scalar(value: Any, key: str, dim: int, box: tuple[float, ...]) -> Field:
    """A scalar field (e.g. a defect's ``face_pressure``): a number or an expression in x, y (, z),
    finite in the box."""
    return parse_field(value, key, dim, 1, box, None)


def _parse_stress(value: Any, dim: int) -> tuple[tuple[float, ...], ...]:
    form = (f"a symmetric {dim}x{dim} tensor of finite numbers "
            + ("[[sxx, sxy], [sxy, syy]]" if dim == 2 else "[[sxx, sxy, sxz], [sxy, syy, syz], [sxz, syz, szz]]"))
    v = _json("remote_stress", value, form)
    if not (isinstance(v, (list, tuple)) and len(v) == dim
            and all(isinstance(r, (list, tuple)) and len(r) == dim and all(_is_number(x) for x in r) for r in v)):
        raise InputError(f"remote_stress must be {form}, got {value!r}")
    s = np.array(v, dtype=float)
    if not np.all(np.isfinite(s)):
        raise InputError(f"remote_stress must be {form}: got non-finite entries {value!r}")
    if np.abs(s - s.T).max() > 1e-12 * np.abs(s).max():
        raise InputError(f"remote_stress must be {form}: it is not symmetric, got {value!r}")
    s = 0.5 * (s + s.T)
    return tuple(tuple(float(x) for x in r) for r in s)


def _parse_table(k: int, tab: Any, dim: int, box: tuple[float, ...]) -> Side:
    key = f"boundary[{k}]"
    if not isinstance(tab, dict):
        raise InputError(f"{key} must be a table with side, support and/or traction, got {tab!r}")
    unknown = sorted(set(tab) - set(TABLE_KEYS))
    if unknown:
        raise InputError(f"{key}: unknown key {unknown[0]!r}; allowed: {', '.join(TABLE_KEYS)}")
    side = tab.get("side")
    if side not in SIDES[dim]:
        extra = " (front and back are sides of a 3D body)" if dim == 2 and side in ("front", "back") else ""
        raise InputError(f"{key}.side must be one of {', '.join(SIDES[dim])}{extra}, got {side!r}")
    if "support" not in tab and "traction" not in tab:
        raise InputError(f"{key} (side {side}) needs a support ({', '.join(SUPPORTS)}) and/or a traction")
    support = tab.get("support", "free")
    if support not in SUPPORTS:
        raise InputError(f"{key}.support must be one of {', '.join(SUPPORTS)}, got {support!r}")
    traction = None
    if "traction" in tab:
        if support == "clamp":
            raise InputError(f"{key}: a clamped side carries no traction (every component is fixed); "
                             f"drop traction or use support = roller or free")
        traction = parse_field(tab["traction"], f"{key}.traction", dim, dim, box, side)
    return Side(side, support, traction)


def parse_loads(params: dict, dim: int) -> LoadSpec | None:
    """The keys ``boundary``, ``body_force``, ``remote_stress`` of ``params`` as a :class:`LoadSpec`, or
    None when none is given (None / empty: the problem's legacy supports and loads apply).

    ``params`` holds validated box lengths (``width``, ``height``; ``depth`` in 3D). InputError naming
    the key (``boundary[2].traction``, ``remote_stress``, ...) and the allowed values.
    """
    box = box_lengths(params, dim)
    tables = _json("boundary", params.get("boundary"), "a list of tables")
    bf, rs = params.get("body_force"), params.get("remote_stress")
    if isinstance(bf, str) and not bf.strip():
        bf = None
    if isinstance(rs, str) and not rs.strip():
        rs = None
    empty = tables is None or (isinstance(tables, (list, tuple)) and len(tables) == 0)
    if empty and bf is None and rs is None:
        return None
    if empty:
        tables = []
    if not isinstance(tables, (list, tuple)):
        raise InputError(f"boundary must be a list of tables ([[boundary]] in TOML) with side, support and/or "
                         f"traction; got {tables!r}")
    if len(tables) > len(SIDES[dim]):
        raise InputError(f"boundary: {len(tables)} tables for {len(SIDES[dim])} sides; each side at most once")
    sides: list[Side] = []
    for k, tab in enumerate(tables):
        s = _parse_table(k, tab, dim, box)
        if any(o.side == s.side for o in sides):
            raise InputError(f"boundary[{k}].side = {s.side!r} is given twice; each side at most once")
        sides.append(s)
    stress = None if rs is None else _parse_stress(rs, dim)
    if stress is not None:
        for k, s in enumerate(sides):
            if s.traction is not None and s.support == "free":
                raise InputError(f"boundary[{k}].traction on the {s.side} side and remote_stress both load that "
                                 f"side: remote_stress applies sigma.n on every side without a support; drop "
                                 f"one of them")
    body = None if bf is None else parse_field(bf, "body_force", dim, dim, box, None)
    return LoadSpec(dim, box, tuple(sides), body, stress)
