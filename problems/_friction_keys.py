"""The friction scene keys of the defect problems (2D ``thin_defect`` and ``fractured``, 3D ``three_d``).

Keys, at the top level of a scene (the default of every defect) and in each ``[[defects]]`` table (that
defect only; a table's key wins over the top level's):

* ``friction`` = ``"none"`` (default) | ``"tresca"`` | ``"coulomb"``;
* ``friction_bound``: Tresca's threshold g >= 0 (a stress: force per area in 3D, per length and unit
  thickness in 2D), a number or an expression in x, y (, z) evaluated at the defect's nodes in the
  reference frame (as ``face_pressure``); only with ``friction = "tresca"``;
* ``friction_coefficient``: Coulomb's coefficient mu_f >= 0 (a number, dimensionless); only with
  ``friction = "coulomb"``.

Refused with one line naming the key (:class:`dualfem.errors.InputError`): an unknown ``friction``, a bound
or coefficient that no defect uses (given with another ``friction``), a Tresca defect without a bound, a
Coulomb defect without a coefficient, negative or non-finite values. :func:`add_friction` turns the parsed
specs into the QP's friction blocks (:func:`dualfem.problems._friction.friction_block`): one Tresca block
over every Tresca defect's node pairs, then one Coulomb block (in that order, after the Signorini block 0).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualfem.errors import InputError
from dualfem.qp import QP

from ._friction import friction_block
from ._load_spec import Field, parse_scalar

KEYS = ("friction", "friction_bound", "friction_coefficient")
KINDS = ("none", "tresca", "coulomb")
#: the top-level defaults of the keys (a problem merges them into its own ``defaults``)
DEFAULTS: dict[str, Any] = {"friction": "none", "friction_bound": None, "friction_coefficient": None}


@dataclass(frozen=True)
class FrictionSpec:
    """The friction of one defect: ``kind`` (one of :data:`KINDS`), Tresca's ``bound`` (a scalar field of
    stresses; None unless tresca), Coulomb's ``coefficient`` (None unless coulomb); ``where``: the key
    prefix of messages (``""`` or ``"defects[3]."``)."""

    kind: str = "none"
    bound: Field | None = None
    coefficient: float | None = None
    where: str = ""


def _given(v: Any) -> bool:
    return v is not None and not (isinstance(v, str) and not v.strip())


def _kind(v: Any, key: str) -> str:
    if not isinstance(v, str) or v.strip().lower() not in KINDS:
        raise InputError(f"{key} must be one of {', '.join(repr(k) for k in KINDS)}, got {v!r}")
    return v.strip().lower()


def _coefficient(v: Any, key: str) -> float:
    if isinstance(v, str):
        try:
            v = float(v)
        except ValueError:
            raise InputError(f"{key} must be a number >= 0 (Coulomb's coefficient), got {v!r}") from None
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v) \
            or v < 0:
        raise InputError(f"{key} must be a finite number >= 0 (Coulomb's coefficient), got {v!r}")
    return float(v)


def _bound(v: Any, key: str, dim: int, box: tuple[float, ...]) -> Field:
    f = parse_scalar(v, key, dim, box)
    if f.constant and float(f.values[0]) < 0:
        raise InputError(f"{key} must be >= 0 (Tresca's threshold, a stress), got {v!r}")
    return f


def parse_friction(top: dict, tables: list[dict], dim: int, box: tuple[float, ...]) -> list[FrictionSpec]:
    """One :class:`FrictionSpec` per defect from the top-level keys ``top`` and each defect's own keys
    (``tables[k]``: the friction keys its ``[[defects]]`` table gives, possibly none); see the module
    docstring for the rules. InputError naming the key on anything refused."""
    kind0 = _kind(top.get("friction", "none"), "friction")
    bound0 = _bound(top["friction_bound"], "friction_bound", dim, box) if _given(top.get("friction_bound")) else None
    coef0 = _coefficient(top["friction_coefficient"], "friction_coefficient") \
        if _given(top.get("friction_coefficient")) else None
    if not tables:
        if kind0 != "none" or bound0 is not None or coef0 is not None:
            raise InputError("friction: the scene has no defect (defects = []), so friction, friction_bound and "
                             "friction_coefficient have nothing to act on; leave them out")
        return []
    own_kinds = {_kind(t["friction"], f"defects[{k}].friction") for k, t in enumerate(tables) if "friction" in t}
    if bound0 is not None and kind0 != "tresca" and "tresca" not in own_kinds:
        raise InputError(f"friction_bound is Tresca's threshold: it needs friction = 'tresca', got "
                         f"friction = {kind0!r}")
    if coef0 is not None and kind0 != "coulomb" and "coulomb" not in own_kinds:
        raise InputError(f"friction_coefficient is Coulomb's coefficient: it needs friction = 'coulomb', got "
                         f"friction = {kind0!r}")
    specs, used_bound, used_coef = [], False, False
    for k, tab in enumerate(tables):
        pre = f"defects[{k}]."
        kind = _kind(tab["friction"], pre + "friction") if "friction" in tab else kind0
        at = pre if "friction" in tab else ""
        own_b, own_c = _given(tab.get("friction_bound")), _given(tab.get("friction_coefficient"))
        if own_b and kind != "tresca":
            raise InputError(f"{pre}friction_bound is Tresca's threshold: it needs friction = 'tresca' on that "
                             f"defect (it has friction = {kind!r})")
        if own_c and kind != "coulomb":
            raise InputError(f"{pre}friction_coefficient is Coulomb's coefficient: it needs friction = 'coulomb' on "
                             f"that defect (it has friction = {kind!r})")
        bound, coef, where = None, None, ""
        if kind == "tresca":
            bound = _bound(tab["friction_bound"], pre + "friction_bound", dim, box) if own_b else bound0
            used_bound |= not own_b
            where = pre if own_b else ""
            if bound is None:
                raise InputError(f"{at}friction = 'tresca' needs friction_bound (the threshold g >= 0, a stress) "
                                 f"in that table or at the top level")
        elif kind == "coulomb":
            coef = _coefficient(tab["friction_coefficient"], pre + "friction_coefficient") if own_c else coef0
            used_coef |= not own_c
            if coef is None:
                raise InputError(f"{at}friction = 'coulomb' needs friction_coefficient (mu_f >= 0) in that table "
                                 f"or at the top level")
        specs.append(FrictionSpec(kind, bound, coef, where))
    if bound0 is not None and not used_bound:
        raise InputError("friction_bound is Tresca's threshold: it needs friction = 'tresca' (at the top level or "
                         f"on a defect without its own bound); got friction = {kind0!r}")
    if coef0 is not None and not used_coef:
        raise InputError("friction_coefficient is Coulomb's coefficient: it needs friction = 'coulomb' (at the top "
                         f"level or on a defect without its own coefficient); got friction = {kind0!r}")
    return specs


def table_keys(table: dict) -> dict:
    """The friction keys a ``[[defects]]`` table gives (for :func:`parse_friction`)."""
    return {k: table[k] for k in KEYS if k in table}


def frictional(specs: list[FrictionSpec]) -> bool:
    """Whether any defect has friction."""
    return any(s.kind != "none" for s in specs)


def add_friction(qp: QP, specs: list[FrictionSpec], points: np.ndarray) -> QP:
    """``qp`` with its friction blocks: Tresca over the node pairs of every Tresca defect (thresholds evaluated
    at ``points`` (dim, m), the pairs' reference coordinates), then Coulomb over the Coulomb defects'. ``qp``
    itself when no defect has friction. InputError when a bound is negative or not finite at a node."""
    if not frictional(specs) or qp.interface is None:
        return qp
    did = qp.interface.defect_id
    blocks = []
    for kind in ("tresca", "coulomb"):
        ks = [k for k, s in enumerate(specs) if s.kind == kind]
        rows = np.flatnonzero(np.isin(did, ks))
        if not rows.size:
            continue
        value = np.zeros(rows.size)
        for k in ks:
            sel = did[rows] == k
            s = specs[k]
            if kind == "coulomb":
                value[sel] = s.coefficient
                continue
            with np.errstate(all="ignore"):
                g = np.broadcast_to(s.bound(points[:, rows[sel]])[0], (int(sel.sum()),))
            if not (np.all(np.isfinite(g)) and np.all(g >= 0)):
                raise InputError(f"{s.where}friction_bound = {s.bound.values[0]!r} must be finite and >= 0 at every "
                                 f"node of its defect (min {np.nanmin(g) if g.size else 0:g})")
            value[sel] = g
        blocks.append(friction_block(qp.interface, qp.n, kind, value, rows))
    return dataclasses.replace(qp, blocks=(*qp.blocks, *blocks), store=None)


def boundary_friction(qp: QP, spec: FrictionSpec, G, weights: np.ndarray, points: np.ndarray) -> QP:
    """``qp`` with the friction of a contact boundary (not a defect: the Signorini problem plugin's foundation):
    one row per contact node (2D: ``G`` (m, n) the tangential displacements, node j = row j of the Signorini
    block), Tresca's threshold evaluated at ``points`` (dim, m). ``qp`` itself without friction."""
    from dualfem.laws import Constraint, Coulomb, Tresca

    if spec.kind == "none":
        return qp
    if spec.kind == "coulomb":
        law = Coulomb(spec.coefficient, components=1)
    else:
        with np.errstate(all="ignore"):
            g = np.broadcast_to(spec.bound(points)[0], (points.shape[1],)).astype(float)
        if not (np.all(np.isfinite(g)) and np.all(g >= 0)):
            raise InputError(f"friction_bound = {spec.bound.values[0]!r} must be finite and >= 0 at every contact "
                             f"node (min {np.nanmin(g) if g.size else 0:g})")
        law = Tresca(g, components=1)
    return dataclasses.replace(qp, blocks=(*qp.blocks, Constraint.make(G, weights, law)), store=None)


def params_label(specs: list[FrictionSpec]) -> str:
    """The friction of each defect as compact text (``QP.params["friction"]``)."""
    def one(s: FrictionSpec) -> str:
        if s.kind == "tresca":
            return f"tresca(g={s.bound.values[0]})"
        return f"coulomb(mu_f={s.coefficient:g})" if s.kind == "coulomb" else "none"

    labels = [one(s) for s in specs]
    return labels[0] if len(set(labels)) == 1 else "[" + ", ".join(labels) + "]"
