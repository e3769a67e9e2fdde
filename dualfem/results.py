"""Results for analysis: ``dualfem.results.load(PATH)`` -> a pandas DataFrame, one row per run.

PATH is a ``dualfem bench`` or ``dualfem stress`` results folder (or its ``results.csv``), or a
stress folder written before both used one store (its ``runs.jsonl``). The columns are the fields of
:class:`dualfem.experiments.row.Row` (documented there; times in seconds ``*_s``, memory in MB
``peak_rss_mb``, errors relative), then the row's extra keys (``scene_*`` parameters, ...).
Dict-valued fields (``solver_params``, ``iterations``, ``coords``) are dicts. Needs pandas
(``pip install 'dualfem[analysis]'``).
"""
from __future__ import annotations

from pathlib import Path

from dualfem.core.errors import InputError, MissingDependency
from dualfem.experiments.row import COLUMNS, Row
from dualfem.experiments.store import read_results
from dualfem.experiments.stress import load_results


def load(path: str | Path):
    """The rows of a bench or stress results folder as a pandas DataFrame (see module docstring)."""
    try:
        import pandas as pd
    except ImportError:
        raise MissingDependency("dualfem.results.load needs pandas: pip install 'dualfem[analysis]'") from None

    p = Path(path)
    if (p / "results.csv").is_file() or p.suffix == ".csv":       # bench and stress: the one store
        rows = [Row.from_dict(r).to_dict() for r in read_results(p)]
    elif (p / "runs.jsonl").is_file() or p.suffix == ".jsonl":    # a stress folder written before it
        rows = [r.to_dict() for r in load_results(p)[1]]
    else:
        raise InputError(f"{str(p)!r} is not a dualfem bench folder (results.csv) or stress folder (runs.jsonl)")
    df = pd.DataFrame(rows)
    first = [c for c in COLUMNS if c in df.columns]
    return df[first + sorted(c for c in df.columns if c not in first)]
