"""Small helpers shared by the bench report modules (reading CSV cells, formatting)."""
from __future__ import annotations

import math

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
    return (str(r.get("scene")), _f(r.get("scene_N")), _f(r.get("scene_delta")))
