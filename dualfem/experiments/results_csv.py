"""The results file of a sweep: ``results.csv`` (and ``results.parquet``) written atomically and read back.

:func:`write_csv` writes tidy rows (the :class:`dualfem.experiments.row.Row` columns first, then the rest
sorted; every record ends with a newline); :func:`read_results` reads them back with numbers parsed (the
:data:`TEXT_COLUMNS` stay text) and skips, with one warning, every unreadable line of a damaged file;
:func:`read_results_checked` returns those lines too (:class:`dualfem.experiments.store.ResultStore` moves
them aside); :func:`check_report_input` refuses what ``dualfem report bench`` cannot read. Also importable
from :mod:`dualfem.experiments.store`, their earlier home.
"""
from __future__ import annotations

import csv
import io
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from dualfem.core.errors import InputError
from dualfem.core.io import RESULTS_ENTRIES, atomic_write, atomic_write_text, check_folder_files, check_input_path
from dualfem.experiments.row import COLUMNS, Row


def write_parquet(path: Path, rows: list[dict]) -> Path | None:
    """The rows as Parquet (atomically), when pandas and pyarrow are installed; else nothing."""
    try:
        import pandas as pd
        import pyarrow  # noqa: F401
    except ImportError:
        return None
    df = pd.DataFrame([(r if isinstance(r, Row) else Row.from_dict(r)).csv_record() for r in rows])
    mixed = [c for c in df.columns if df[c].dtype == object
             and len({type(v) for v in df[c] if v is not None}) > 1]
    for c in mixed:                   # a column of mixed types (e.g. numbers and text) is kept as text
        df[c] = df[c].map(lambda v: None if v is None else str(v))
    return atomic_write(path, lambda tmp: df.to_parquet(tmp, index=False))


def write_csv(path: str | Path, rows: list[dict]) -> Path:
    """Write tidy rows to CSV atomically (the :class:`Row` columns first, then the rest sorted)."""
    rows = [(r if isinstance(r, Row) else Row.from_dict(r)).csv_record() for r in rows]
    extra = sorted({k for r in rows for k in r} - set(COLUMNS))
    cols = COLUMNS + extra
    rows = sorted(rows, key=lambda r: (str(r.get("kind")), str(r.get("label")), str(r.get("variant")),
                                       str(r.get("tier")), str(r.get("run_id"))))
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in cols})
    return atomic_write_text(path, buf.getvalue())


#: columns that hold text even when it looks like a number (a hex run id such as "5e12..." is not 5e12)
TEXT_COLUMNS = {"run_id", "kind", "spec", "scene", "scene_key", "label", "solver", "variant", "tier", "status",
                "claimed_status", "grade", "message", "ref_solver", "git", "started_utc", "cpu", "threads", "python",
                "platform", "versions", "axis", "solver_params", "iterations", "coords"}


def read_results(path: str | Path, warn: Callable[[str], None] | None = None) -> list[dict]:
    """Rows of a results.csv (or of the results.csv inside a directory), numbers parsed.

    A damaged file (cut by a kill or a full disk, or edited by hand) gives its readable rows: every
    unreadable line is skipped with one warning (``warn``, default a ``dualfem: warning:`` line on
    stderr); nothing is changed on disk (:class:`ResultStore` moves the bad part aside). A file that
    is not a results.csv at all (no header with run_id, kind, status) is an InputError.
    """
    rows, bad = read_results_checked(path)
    if bad:
        (warn or _warn_stderr)(f"{len(bad)} unreadable line(s) of {str(_csv_path(path))!r} skipped (a cut or "
                               f"damaged write?): {_lines(bad)}; every other row is read")
    return rows


#: a run id names its file in rows/: letters, digits and ``_.:=+,@-``, no path separator, not starting with "."
_SAFE_ID = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.:=+,@-]{0,199}")


def _warn_stderr(msg: str) -> None:
    print(f"dualfem: warning: {msg}", file=sys.stderr)


def _lines(bad: list[tuple[int, str]]) -> str:
    nums = [str(n) for n, _ in bad]
    more = f" and {len(nums) - 5} more" if len(nums) > 5 else ""
    return ("line " if len(nums) == 1 else "lines ") + ", ".join(nums[:5]) + more


def _csv_path(path: str | Path) -> Path:
    path = Path(path)
    return path / "results.csv" if path.is_dir() else path


#: the columns of a bench results.csv that ``dualfem report bench`` cannot do without (every bench writes them)
REPORT_COLUMNS = ("scene", "scene_key", "label", "n_unknowns", "total_s")


def check_report_input(path: str | Path) -> None:
    """Refuse, in one InputError, results that ``dualfem report bench`` cannot read: a folder holding a FIFO
    or a device, a file that is not a bench results.csv, or one without a column of :data:`REPORT_COLUMNS`
    (a hand-made minimal CSV)."""
    p = Path(path)
    check_folder_files(p if p.is_dir() else p.parent, "RESULTS", only=None if p.is_dir() else RESULTS_ENTRIES)
    csv_path = check_input_path(_csv_path(p), "results file")
    with open(csv_path, encoding="utf-8", errors="replace", newline="") as fh:
        header = next(csv.reader(fh), [])
    missing = [c for c in REPORT_COLUMNS if c not in header]
    if missing and {"run_id", "kind", "status"} <= set(header):     # else the loader says what it is not
        raise InputError(f"{str(csv_path)!r} lacks the column(s) {', '.join(missing)} that every 'dualfem bench' "
                         f"results.csv has: it cannot be reported (write it with dualfem bench)")


def read_results_checked(path: str | Path) -> tuple[list[dict], list[tuple[int, str]]]:
    """(rows, bad) of a results.csv: the readable rows, and (line number, raw text) of every unreadable
    record (a cut last line, a wrong number of fields, no run id, undecodable bytes, NUL bytes)."""
    path = check_input_path(_csv_path(path), "results file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read {str(path)!r}: {exc.strerror or exc}") from None
    text = data.decode("utf-8", errors="surrogateescape")    # a line with undecodable bytes is a bad line
    lines = text.splitlines(keepends=True)
    if not lines:
        raise InputError(f"{str(path)!r} is not a dualfem bench results.csv (empty)")
    reader = csv.reader(io.StringIO(text.replace("\0", "")) if "\0" not in lines[0] else io.StringIO(""))
    try:
        header = next(reader)
    except (StopIteration, csv.Error):
        header = []
    missing = {"run_id", "kind", "status"} - {h for h in header if _utf8(h)}
    if missing:
        raise InputError(f"{str(path)!r} is not a dualfem bench results.csv (no column {', '.join(sorted(missing))})")
    rows: list[dict] = []
    bad: list[tuple[int, str]] = []
    done = reader.line_num
    while True:
        try:
            rec = next(reader)
        except StopIteration:
            break
        except csv.Error:
            bad.append((done + 1, "".join(lines[done:])))
            done = len(lines)
            break
        raw = "".join(lines[done:reader.line_num])
        first, done = done + 1, reader.line_num
        if not rec:
            continue
        complete = raw.endswith("\n") and "\0" not in raw     # write_csv ends every record with a newline
        if not complete or not _utf8(raw) or len(rec) != len(header):
            bad.append((first, raw))
            continue
        try:
            r = {k: (v if k in TEXT_COLUMNS else _parse(v)) for k, v in zip(header, rec)}
        except (TypeError, ValueError):
            bad.append((first, raw))
            continue
        if not r.get("kind") or not _SAFE_ID.fullmatch(str(r.get("run_id") or "")) or ".." in r["run_id"]:
            bad.append((first, raw))      # no run id, or one that cannot name a file in rows/
            continue
        rows.append(r)
    if done < len(lines):
        bad.append((done + 1, "".join(lines[done:])))
    return rows, bad


def _utf8(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _parse(v: str | None) -> Any:
    if v is None or v == "":
        return None
    if v in ("True", "False"):
        return v == "True"
    try:
        f = float(v)
    except ValueError:
        return v
    return int(f) if f.is_integer() and "." not in v and "e" not in v.lower() and "inf" not in v.lower() else f

