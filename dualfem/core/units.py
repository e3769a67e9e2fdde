"""A problem's unit map: how its scene parameters change with the unit system.

A problem plugin declares ``unit_map = UnitMap({...})`` (:attr:`dualfem.core.problem.Problem.unit_map`):
scene key -> the kind of quantity it holds, in the order the keys are converted. The stress grid's
``units`` axis (:mod:`dualfem.experiments.stress_grid`) converts a scene with :meth:`UnitMap.convert`
and never names a problem; a problem without a unit map has no units axis.

A change of units multiplies stresses by ``stress`` (new stress units per old one) and lengths by
``length`` (new length units per old one). The kinds (:data:`KINDS`):

* ``"stress"``: x ``stress`` (Young's modulus, a load scale);
* ``"length"``: x ``length`` (width, height, an indentation);
* ``"length_if_set"``: x ``length`` where the scene sets the key, else left out (a mesh size whose
  default means "derived from N");
* ``"length/stress"``: x ``length / stress`` (the defect parameter delta: the interface pressure is
  the jump [u] / delta);
* ``"points"``: a list of points, each coordinate x ``length``;
* ``"defect_tables"``: ``[[defects]]`` tables (their ``points`` lengths, own ``delta`` a length per
  stress, ``face_pressure`` an expression in x, y); given, they replace the ``"points"`` keys;
* ``"body_force"``: a force per volume (stress / length; the stress is carried by a ``"stress"``
  key such as ``load_scale``): each component / ``length``, an expression evaluated at the unscaled
  coordinates;
* ``"traction_tables"``: ``[[boundary]]`` tables whose ``traction`` expressions are evaluated at the
  unscaled coordinates (a traction is a stress, carried by the load scale);
* ``"stress_field"``: an expression in x, y of a stress, evaluated at the unscaled coordinates,
  unless it is one of :attr:`UnitMap.scaling_names` (named loads that scale with the body's width);
* ``"length_field"``: an expression in x of a length: ``length * g(x / length)``;
* ``"file"``: a file of lengths (e.g. ``defects_file``) that cannot be converted: a scene that sets
  it has no units axis (InputError).
* ``"stress_value"``: a stress given as a number (x ``stress``) or an expression in x, y (``stress *
  (g(x / length, y / length))``), left out when not set (None): Tresca's ``friction_bound``, also in
  ``[[defects]]`` tables.

Under such a change the solution maps exactly: x by ``length``, the nodal forces mu by
``stress * length``. A field given as a Python function cannot be converted (InputError).
"""
from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dualfem.core.errors import InputError

#: the kinds of quantity a unit map knows (module docstring)
KINDS = ("stress", "length", "length_if_set", "length/stress", "points", "defect_tables", "body_force",
         "traction_tables", "stress_field", "length_field", "file", "stress_value")


@dataclass(frozen=True)
class UnitMap:
    """Scene key -> kind of quantity (:data:`KINDS`), converted in this order; ``scaling_names``: values
    of a ``"stress_field"`` key that are names scaling by themselves (kept as they are)."""

    kinds: Mapping[str, str]
    scaling_names: tuple[str, ...] = ()
    replaced: tuple[str, ...] = field(init=False, default=())

    def __post_init__(self) -> None:
        bad = [f"{k}: {v!r}" for k, v in self.kinds.items() if v not in KINDS]
        if bad:
            raise InputError(f"unit map: unknown kind {bad[0]} (kinds: {', '.join(KINDS)})")
        object.__setattr__(self, "kinds", dict(self.kinds))
        object.__setattr__(self, "replaced", tuple(k for k, v in self.kinds.items() if v == "points"))

    def convert(self, defaults: Mapping[str, Any], base: dict, stress: float, length: float) -> dict:
        """The scene ``base`` (over ``defaults``) with the same physics in units ``stress`` times and
        ``length`` times the old ones (module docstring): a new dict, the keys it does not map kept."""
        d = {**defaults, **base}
        out = dict(base)
        tables = any(v == "defect_tables" and base.get(k) for k, v in self.kinds.items())
        for k, kind in self.kinds.items():
            if kind == "stress":
                out[k] = float(d[k]) * stress
            elif kind == "length":
                out[k] = float(d[k]) * length
            elif kind == "length_if_set":
                if k in base:
                    out[k] = float(base[k]) * length
            elif kind == "length/stress":
                out[k] = float(d[k]) * length / stress
            elif kind == "points":
                if not tables:
                    out[k] = [[float(c) * length for c in pt] for pt in np.asarray(d[k], dtype=float)]
            elif kind == "defect_tables":
                if base.get(k):      # the tables replace the single segment (left at its default)
                    out[k] = scaled_defects(base[k], length, stress)
                    for r in self.replaced:
                        out.pop(r, None)
            elif kind == "body_force":
                _scaled_body_force(out, k, d, length)
            elif kind == "traction_tables":
                _scaled_tractions(out, k, d, length)
            elif kind == "stress_field":
                v = _not_callable(k, d[k])
                if isinstance(v, str) and v.strip() not in self.scaling_names and length != 1:
                    out[k] = scaled_expression(v.strip(), length)
            elif kind == "file":
                if base.get(k):
                    raise InputError(f"scene_in_units: {k} = {base[k]!r} holds lengths in a file that cannot be "
                                     f"converted to other units; write its defects as [[defects]] tables")
            elif kind == "stress_value":
                if d.get(k) is not None:
                    out[k] = scaled_stress(d[k], length, stress)
            else:   # "length_field"
                g = _not_callable(k, d[k])
                out[k] = f"{float(length)!r} * ({scaled_expression(str(g).strip(), length)})" if length != 1 else g
        return out


def _not_callable(key: str, value: Any) -> Any:
    if callable(value):
        raise InputError(f"scene_in_units: the {key} given as a Python function cannot be converted to other units")
    return value


def scaled_expression(expr: str, length: float) -> str:
    """A load expression in ``x``, ``y`` rewritten for coordinates ``length`` times larger
    (checked by the one expression sandbox, :func:`dualfem.core.expressions.rewrite`)."""
    from dualfem.core.expressions import rewrite

    return rewrite(expr, {v: f"{v} / {float(length)!r}" for v in ("x", "y")}, parameter="load",
                   variables=("x", "y"), hint="use f1, f2, f3 or a numpy expression in x, y")


def scaled_defects(tables, length: float, stress: float) -> list[dict]:
    """``[[defects]]`` tables with their points (lengths) and own delta (length / stress) converted."""
    out = []
    for tab in tables:
        t = dict(tab)
        if "points" in t:
            t["points"] = [[float(c) * length for c in pt] for pt in t["points"]]
        if "delta" in t:
            t["delta"] = float(t["delta"]) * length / stress
        if isinstance(t.get("face_pressure"), str) and length != 1:
            t["face_pressure"] = scaled_expression(t["face_pressure"], length)
        if t.get("friction_bound") is not None:
            t["friction_bound"] = scaled_stress(t["friction_bound"], length, stress)
        out.append(t)
    return out


def scaled_stress(v: Any, length: float, stress: float) -> Any:
    """A stress given as a number or an expression in x, y, for units ``stress`` times and coordinates
    ``length`` times the old ones (kind ``"stress_value"``)."""
    if isinstance(v, str):
        return f"{float(stress)!r} * ({scaled_expression(v.strip(), length) if length != 1 else v.strip()})"
    return float(v) * stress


def _value(v: Any) -> Any:
    """A JSON text of a list or table (as ``--set`` gives it) decoded; anything else as it is."""
    return json.loads(v) if isinstance(v, str) and v.strip()[:1] in "[{" else v


def _expr(v: Any, length: float) -> Any:
    return scaled_expression(v, length) if isinstance(v, str) else v


def _scaled_body_force(out: dict, key: str, d: dict, length: float) -> None:
    """A body force (force per volume: stress / length; docs/loads.md) for coordinates ``length`` times
    larger, into ``out``: each component divided by ``length``, expressions at the unscaled coordinates."""
    if length == 1:
        return
    bf = _value(d.get(key))
    if isinstance(bf, (list, tuple)):
        out[key] = [f"({_expr(v, length)}) / {float(length)!r}" if isinstance(v, str) else float(v) / length
                    for v in bf]


def _scaled_tractions(out: dict, key: str, d: dict, length: float) -> None:
    """``[[boundary]]`` tables (docs/loads.md) for coordinates ``length`` times larger, into ``out``: each
    ``traction`` (a stress) evaluated at the unscaled coordinates."""
    if length == 1:
        return
    tables = _value(d.get(key))
    if isinstance(tables, (list, tuple)) and tables:
        out[key] = [{**t, "traction": [_expr(v, length) for v in _value(t["traction"])]}
                    if isinstance(t, dict) and isinstance(_value(t.get("traction")), (list, tuple)) else t
                    for t in tables]
