"""``dualfem report html RESULTS... --out DIR``: a self-contained interactive dashboard, ``DIR/index.html``.

One HTML file that opens without a network: plotly.js (the ``plotly`` Python package's copy,
``pip install 'dualfem[html]'``) and the data are embedded inline. It shows, for the scene (its identity:
name and the grid keys that vary, :class:`dualfem.reports._bench_util.SceneId`), delta, tier and solvers
selected in its side panel (plain JavaScript filtering the embedded JSON):

* the work-precision plot: time (setup + solve, s) against the relative energy-norm error against the
  certified reference (or the evaluator's KKT error), one point per run, hollow when not solved; with
  convergence curves in the results (bench spec ``curves = true``, ``curves.csv``) the median curve
  per solver (of its tightest tier) with its interquartile band; the floor as a dashed line and the
  reference solver's own runs (error 0 against themselves) as a dotted line, not as points; by default
  one panel per scene and delta (more than 24: the page opens on one scene), or one panel per solver
  family; colours and markers of :mod:`dualfem.post.style`;
* success and correct rates per solver and tier, the ranking tables and, with ``show_targets``, the
  performance targets of ``dualfem report bench`` (the same functions compute them:
  :mod:`dualfem.reports._dash_data`).

The page marks itself for tests: ``data-dash-rendered="ok"`` on ``<html>`` once every plot is drawn;
any JavaScript error or unhandled rejection is written into ``<pre id="dash-errors">`` (and
``data-dash-error="1"``).

Output: ``DIR/index.html`` only, written atomically. DIR may be new, empty, or hold an earlier dashboard
(replaced); a DIR holding other files, or an ``index.html`` this command did not write, is refused unless
``force`` (then only ``index.html`` is written, nothing else is touched).
"""
from __future__ import annotations

import json
import re
from importlib import resources
from pathlib import Path

from dualfem.core.errors import InputError, MissingDependency
from dualfem.core.io import atomic_write_text, check_output_path
from dualfem.reports._dash_data import payload

#: the mark of a page written by this module (its ``<meta name="generator">``)
GENERATOR = '<meta name="generator" content="dualfem report html">'
#: the file written in DIR
INDEX = "index.html"
_PLACEHOLDER = re.compile(r"@@([A-Z_]+)@@")


def plotly_js() -> str:
    """The plotly.js bundle of the installed ``plotly`` package (MissingDependency when it is not installed)."""
    try:
        from plotly.offline import get_plotlyjs
    except ImportError:
        raise MissingDependency("dualfem report html needs plotly: pip install 'dualfem[html]' "
                                "(or pip install plotly)") from None
    return get_plotlyjs()


def _template(name: str) -> str:
    return (resources.files("dualfem.reports") / "templates" / name).read_text(encoding="utf-8")


def _script_safe(text: str) -> str:
    """Text that cannot end its ``<script>`` element early (``</`` written ``<\\/``: the same in JS strings)."""
    return re.sub(r"</(?=script)", r"<\\/", text, flags=re.IGNORECASE)


def render(data: dict, js_bundle: str) -> str:
    """The page for the dashboard ``data`` (:func:`dualfem.reports._dash_data.payload`) with the plotly.js
    source ``js_bundle`` inlined."""
    # JSON inside <script type="application/json">: "<" escaped, so no "</script>" or "<!--" can occur
    blob = json.dumps(_finite(data), separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")
    values = {"TITLE": _escape(str(data.get("title") or "dualfem dashboard")),
              "MAX_SERIES": str(int(data.get("max_series", 10))),
              "DASH_CSS": _template("dashboard.css"), "DASH_LIB": _script_safe(_template("dashboard_lib.js")),
              "DASH_JS": _script_safe(_template("dashboard.js")),
              "PLOTLY_JS": _script_safe(js_bundle), "DATA_JSON": blob}
    # one pass: inserted text (plotly.js, the data) is never scanned for placeholders again
    return _PLACEHOLDER.sub(lambda m: values[m.group(1)], _template("dashboard.html"))


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def _finite(obj):
    """``obj`` with every non-finite float replaced by None (JSON null)."""
    if isinstance(obj, float):
        return obj if obj == obj and obj not in (float("inf"), float("-inf")) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def is_dashboard(path: Path) -> bool:
    """Whether ``path`` is a page written by this module (its head carries :data:`GENERATOR`)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            return GENERATOR in fh.read(4096)
    except OSError:
        return False


def check_out_dir(out: str | Path, force: bool = False) -> Path:
    """The path of ``DIR/index.html`` after checking DIR (module docstring), before any work: InputError
    for a DIR that is a file, that cannot be written, or (unless ``force``) that holds other files or an
    ``index.html`` this module did not write."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {str(out)!r} is a file; give a folder (the dashboard is written to DIR/{INDEX})")
    index = out / INDEX
    if out.is_dir() and not force:
        others = sorted(p.name for p in out.iterdir() if p.name != INDEX and not p.name.startswith(f".{INDEX}."))
        if others:
            more = f" and {len(others) - 3} more" if len(others) > 3 else ""
            raise InputError(f"--out {str(out)!r} holds files that 'dualfem report html' did not write "
                             f"({', '.join(others[:3])}{more}); give a new or empty folder, or --force to write "
                             f"{INDEX} beside them")
        if index.exists() and not is_dashboard(index):
            raise InputError(f"{str(index)!r} exists and is not a dualfem dashboard; give another --out, or --force "
                             "to replace it")
    return check_output_path(index, "--out")


def build_dashboard(results: list[str | Path], out: str | Path, *, force: bool = False, shift: float = 10.0,
                    ours: list[str] | None = None, err_target: float = 1e-8, command: str = "",
                    show_targets: bool = False) -> Path:
    """Write ``out/index.html`` from the results folders ``results`` (later ones replace the rows of earlier
    ones that measure the same thing); returns its path. Everything is checked (DIR, plotly, the results)
    before anything is written; ``shift`` (s), ``ours``, ``err_target`` and ``show_targets`` as for
    ``dualfem report bench``."""
    index = check_out_dir(out, force)
    bundle = plotly_js()
    data = payload(list(results), shift=shift, ours=ours, err_target=err_target, command=command,
                   show_targets=show_targets)
    atomic_write_text(index, render(data, bundle))
    return index
