"""Results for analysis: ``dualfem.results.load(PATH)`` -> a pandas DataFrame.

PATH is a ``dualfem bench`` or ``dualfem stress`` results folder (or its ``results.csv``), or a
stress folder written before both used one store (its ``runs.jsonl``). Needs pandas
(``pip install 'dualfem[analysis]'``).

**Two tables** (``table=``):

* ``"runs"`` (the default): one row per row of ``results.csv``. The columns are the fields of
  :class:`dualfem.experiments.row.Row` (documented there; times in seconds ``*_s``, memory in MB
  ``peak_rss_mb``, errors relative), then the row's extra keys (``scene_*`` parameters, ...).
  Dict-valued fields (``solver_params``, ``iterations``, ``coords``) are dicts.
* ``"curves"``: the convergence curves of a bench run with ``curves = true``
  (:mod:`dualfem.experiments.curves`): one row per (run, timed repeat, sample), columns exactly ``run_id,
  solver, tier, scene_key, iteration, time_s, error, error_kind, repeat`` (``run_id`` joins the runs table;
  ``repeat`` = 1, 2, ... numbers the run's timed repeats, whose curves differ in their times; ``time_s``
  = setup + solve time at the sample, the monitor's own time excluded; ``error`` relative: the
  energy-norm error against the certified reference when ``error_kind == "reference"``, else the
  evaluator's KKT error, ``"kkt"``; NaN where it could not be computed). A folder without curves
  (``curves = false``, a stress folder, or only solvers without iterates) gives no rows, with the columns.

**Row kinds** (the ``kind`` column of the runs table), and ``kind=`` to choose them:

* ``run``: one solver on one scene at one tolerance tier (``dualfem bench``): the competitors;
* ``reference``: the certified exact solve a bench scene's errors are measured against
  (:mod:`dualfem.experiments.reference`): solved at a stricter tolerance than any tier, by one of the
  solvers also benchmarked;
* ``floor``: one sparse factorization + one solve of the unconstrained K (``solver`` ``floor_splu``,
  ``floor_pardiso``, ...): the lower bound on the time of any direct method, not a QP solve;
* ``stress``: one point of the numerical-stability grid (``dualfem stress``);
* ``compare``: one solver against a certified reference (``dualfem compare``).

They are kept apart because they are different measurements that share columns: a
``groupby("solver")`` over every row would mix a reference solve (another tolerance, untimed
against the others) into that solver's runs and count floors as solvers. ``kind="run"`` (the
default) gives the bench's runs; ``kind="stress"`` a stress folder's; a name or a list of names
chooses others, ``None`` or ``"all"`` every row.
"""
from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path

from dualfem.core.errors import InputError, MissingDependency
from dualfem.experiments.curves import COLUMNS as CURVE_COLUMNS
from dualfem.experiments.curves import read_curves
from dualfem.experiments.row import COLUMNS, Row
from dualfem.experiments.store import read_results
from dualfem.experiments.stress import load_results

#: the tables :func:`load` reads
TABLES = ("runs", "curves")
#: the row kinds of the runs table (module docstring)
KINDS = ("run", "reference", "floor", "stress", "compare")


def load(path: str | Path, table: str = "runs", kind: str | Sequence[str] | None = "run"):
    """A table of a bench or stress results folder as a pandas DataFrame (see module docstring).

    ``table``: ``"runs"`` or ``"curves"``; ``kind`` (runs table only): a row kind of :data:`KINDS`, a
    list of them, or ``None`` / ``"all"`` for every row. InputError for another table or kind, or a
    PATH that is not a results folder.
    """
    if table not in TABLES:
        raise InputError(f"table must be one of {', '.join(TABLES)}, got {table!r}")
    kinds = _kinds(kind)
    try:
        import pandas as pd
    except ImportError:
        raise MissingDependency("dualfem.results.load needs pandas: pip install 'dualfem[analysis]'") from None

    p = Path(path)
    if table == "curves":
        return _curves(p, pd)
    if (p / "results.csv").is_file() or p.suffix == ".csv":       # bench and stress: the one store
        rows = [Row.from_dict(r).to_dict() for r in read_results(p)]
    elif (p / "runs.jsonl").is_file() or p.suffix == ".jsonl":    # a stress folder written before it
        rows = [r.to_dict() for r in load_results(p)[1]]
    else:
        raise InputError(f"{str(p)!r} is not a dualfem bench folder (results.csv) or stress folder (runs.jsonl)")
    if kinds is not None:
        held = sorted({str(r.get("kind")) for r in rows})
        rows = [r for r in rows if r.get("kind") in kinds]
        if not rows and held:          # e.g. the default kind="run" on a stress folder: say what is there
            warnings.warn(f"{str(p)!r} holds no rows of kind {', '.join(sorted(kinds))}; its kinds: "
                          f"{', '.join(held)} (load(..., kind={held[0]!r}) or kind='all')", stacklevel=2)
    df = pd.DataFrame(rows, columns=None if rows else COLUMNS)
    first = [c for c in COLUMNS if c in df.columns]
    return df[first + sorted(c for c in df.columns if c not in first)]


def _kinds(kind: str | Sequence[str] | None) -> set[str] | None:
    """The set of row kinds asked for (None: every row); InputError naming ``kind`` otherwise."""
    if kind is None or kind == "all":
        return None
    names = [kind] if isinstance(kind, str) else list(kind) if isinstance(kind, (list, tuple, set, frozenset)) else []
    if not names or any(not isinstance(k, str) or k not in KINDS for k in names):
        raise InputError(f"kind must be one of {', '.join(KINDS)}, a list of them, None or 'all'; got {kind!r}")
    return set(names)


def _curves(p: Path, pd):
    """The curves table of folder ``p`` (or of a curves.csv): only curves whose run row is in results.csv."""
    folder = p.parent if p.suffix == ".csv" else p
    csv_path = p if p.suffix == ".csv" and p.name != "results.csv" else folder / "curves.csv"
    if not csv_path.is_file():
        if not ((folder / "results.csv").is_file() or (folder / "runs.jsonl").is_file()):
            raise InputError(f"{str(p)!r} is not a dualfem bench folder (results.csv, curves.csv)")
        kinds = {"time_s": "float64", "error": "float64", "iteration": "int64", "repeat": "int64"}
        return pd.DataFrame({c: pd.Series(dtype=kinds.get(c, "object")) for c in CURVE_COLUMNS})
    recs = read_curves(csv_path)
    if (folder / "results.csv").is_file():       # never a sample of a run whose row is not there
        runs = {r["run_id"] for r in read_results(folder / "results.csv", warn=lambda msg: None)}
        recs = [r for r in recs if r["run_id"] in runs]
    df = pd.DataFrame(recs, columns=list(CURVE_COLUMNS))
    return df.astype({"iteration": "int64", "time_s": "float64", "error": "float64", "repeat": "int64"})
