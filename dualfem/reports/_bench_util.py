"""Small helpers shared by the bench report modules (reading CSV cells, formatting)."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

#: the benchmark's cast, named once: our solvers, held to the performance targets (``dualfem report bench
#: --ours``), and the third-party competitors they are compared with
OURS = ("uzawa", "uzawa_auto", "pdas")
COMPETITORS = ("clarabel", "osqp")


def _f(v) -> float:
    """A CSV cell as a float (NaN if empty or not a number)."""
    try:
        f = float(v)
    except (TypeError, ValueError):
        return float("nan")
    return f


def _fmt(v, spec=".3g") -> str:
    f = _f(v)
    return "n/a" if not math.isfinite(f) else format(f, spec)


def _scene_of(r: dict) -> tuple:
    return (scene_name(r), _f(r.get("scene_N")), _f(r.get("scene_delta")))


#: columns named ``scene_*`` that are not scene parameters
_NOT_PARAMS = frozenset({"scene_key", "scene_name"})
#: scene parameters drawn as panel columns (not part of a figure's identity)
PANEL_KEYS = frozenset({"delta"})
#: mesh-size parameters named in a figure's identity whenever the runs give them
SIZE_NAMES = frozenset({"N", "mesh_size"})


def scene_name(r: dict) -> str:
    """The scene's name as the user gave it: a preset or library name (``f2``, ``curved``), or a scene
    file's stem (``benchmarks/scenes/inclined_biaxial.toml`` -> ``inclined_biaxial``)."""
    s = str(r.get("scene") or r.get("scene_name") or "?")
    return Path(s).stem if s.endswith((".toml", ".npz", ".mat")) or "/" in s else s


def _cell(v) -> str:
    """A scene parameter's value as text (numbers with ``:g``; empty and NaN cells as "")."""
    if v is None or v == "":
        return ""
    f = _f(v)
    if math.isfinite(f) and not isinstance(v, bool):
        return f"{f:g}"
    return "" if isinstance(v, float) else str(v)


@dataclass(frozen=True, order=True)
class SceneId:
    """What one work-precision figure shows: a scene (:func:`scene_name`) and the values of its grid
    keys that vary between its runs (``size``: sorted (key, value text) pairs; delta excluded, it is a
    panel column). A scene given by ``mesh_size`` has no ``N`` and needs none."""

    scene: str
    size: tuple[tuple[str, str], ...] = ()

    @property
    def label(self) -> str:
        """``f2, N = 64`` / ``plate, mesh_size = 0.02`` / ``plate``."""
        return ", ".join([self.scene] + [f"{k} = {v}" for k, v in self.size])

    @property
    def slug(self) -> str:
        """A file-name part: ``f2_N64``, ``plate_mesh_size0.02``, ``plate`` (only ``[A-Za-z0-9_.-]``)."""
        text = "_".join([self.scene] + [f"{k}{v}" for k, v in self.size])
        return re.sub(r"[^A-Za-z0-9_.-]+", "-", text)


def size_keys(runs: list[dict]) -> dict[str, tuple[str, ...]]:
    """Per scene name, the scene parameters (columns ``scene_<key>``, not delta) whose values differ
    between its runs (the keys that tell its figures apart), and the size keys of :data:`SIZE_NAMES`
    that its runs give (named even when they do not vary)."""
    vals: dict[str, dict[str, set[str]]] = {}
    for r in runs:
        per = vals.setdefault(scene_name(r), {})
        for k, v in r.items():
            if k.startswith("scene_") and k not in _NOT_PARAMS and k[6:] not in PANEL_KEYS:
                per.setdefault(k[6:], set()).add(_cell(v))
    return {s: tuple(sorted(k for k, v in per.items() if len(v) > 1 or (k in SIZE_NAMES and v != {""})))
            for s, per in vals.items()}


def scene_id(r: dict, keys: dict[str, tuple[str, ...]]) -> SceneId:
    """The :class:`SceneId` of one row, given :func:`size_keys` of the rows it is grouped with."""
    name = scene_name(r)
    return SceneId(name, tuple((k, _cell(r.get(f"scene_{k}"))) for k in keys.get(name, ())))


def group_scenes(runs: list[dict]) -> dict[SceneId, list[dict]]:
    """The rows per :class:`SceneId`, ordered by scene name, then by median unknowns (smallest first)."""
    keys = size_keys(runs)
    out: dict[SceneId, list[dict]] = {}
    for r in runs:
        out.setdefault(scene_id(r, keys), []).append(r)

    def size(item) -> float:
        ns = sorted(_f(r.get("n_unknowns")) for r in item[1] if math.isfinite(_f(r.get("n_unknowns"))))
        return ns[len(ns) // 2] if ns else math.inf

    return dict(sorted(out.items(), key=lambda it: (it[0].scene, size(it), it[0].size)))


def unknowns(rows: list[dict]) -> float:
    """The median number of unknowns of ``rows`` (NaN if none is recorded)."""
    ns = sorted(_f(r.get("n_unknowns")) for r in rows if math.isfinite(_f(r.get("n_unknowns"))))
    return ns[len(ns) // 2] if ns else float("nan")
