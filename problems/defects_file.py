"""Defect networks in files: the scene key ``defects_file`` (CSV or JSON), read and written.

A file holds the same defects as a scene's ``[[defects]]`` tables, for networks too large to write by
hand (field data of fracture networks: hundreds to thousands of segments or disks). Lengths are in
the scene's unit, points in the reference (unrotated) frame of the body. Formats (docs/fractured.md):

* CSV, 2D, one segment per row: header ``x1,y1,x2,y2`` (``delta`` optional): the points (x1, y1),
  (x2, y2) of a straight defect, its normal the direction turned by +90 degrees (as for ``points``).
* CSV, 2D, polylines: header ``defect,x,y`` (``delta`` optional): the rows with the same ``defect``
  id (an integer) are the points of one polyline, in order; the ids' rows must be consecutive, and a
  ``delta`` must be the same on every row of a defect.
* CSV, 3D: header ``cx,cy,cz,nx,ny,nz,radius`` (disks) or ``cx,cy,cz,nx,ny,nz,a,b,dx,dy,dz``
  (ellipses: semi-axes a, b and the in-plane direction (dx, dy, dz) of a), ``delta`` optional; a
  header with both ``radius`` and ``a,b,dx,dy,dz`` mixes them: a row gives either ``radius`` or all of
  ``a,b,dx,dy,dz`` and leaves the others empty.
* JSON (``.json``), 2D or 3D: a list of objects with the keys of the scene's ``[[defects]]`` tables
  (2D: ``points``, ``curve``, ``delta``, ``face_pressure``; 3D: ``shape`` and its keys).

Columns may come in any order; names are case-sensitive; an empty ``delta`` cell is the scene's
``delta``. :func:`read_defects` returns the tables (checked here: the header, every cell a finite
number, the counts); the problem checks them as it checks ``[[defects]]`` tables (inside the body,
no crossings, the mesh size estimate) before anything is meshed. :func:`write_defects` writes tables
back (CSV when every defect fits a CSV form, else refused naming JSON). Errors are
:class:`~dualfem.errors.InputError` naming the file, and the row (counted from 1, the header is row 1)
and column of a bad cell.
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path
from typing import Any

from dualfem.errors import InputError

#: the largest defects file read (checked with stat, before it is opened)
MAX_BYTES = 64 * 2 ** 20
#: the most defects (2D: segments or polylines; 3D: disks or ellipses) in one file, and rows in a CSV
MAX_DEFECTS = 100_000
MAX_ROWS = 1_000_000
FORMATS = (".csv", ".json")
SEGMENT = ("x1", "y1", "x2", "y2")
POLYLINE = ("defect", "x", "y")
DISK = ("cx", "cy", "cz", "nx", "ny", "nz", "radius")
ELLIPSE = ("cx", "cy", "cz", "nx", "ny", "nz", "a", "b", "dx", "dy", "dz")
_ELLIPSE_ONLY = ("a", "b", "dx", "dy", "dz")


def _suffix(path: Path, name: str) -> str:
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise InputError(f"{name} must be a .csv or .json file, got {str(path)!r}")
    return suffix


def _dim(dim: Any) -> int:
    if dim not in (2, 3):
        raise InputError(f"a defects file is 2D or 3D, got dim = {dim!r}")
    return int(dim)


# --------------------------------------------------------------------------------------- reading
def file_or_tables(defects_file, tables, dim: int) -> tuple[list | None, str]:
    """The defect tables of a scene: those of ``defects_file`` (:func:`read_defects`) when it is set, with the
    words naming it in messages; else ``tables`` (the ``[[defects]]`` key as given, None when not given) and ''.
    Both set, or a ``defects_file`` that is not a path: InputError."""
    if defects_file is None or (isinstance(defects_file, str) and not defects_file.strip()):
        return tables, ""
    if not isinstance(defects_file, str):
        raise InputError(f"defects_file must be a path to a .csv or .json file, got {defects_file!r}")
    if tables is not None:
        raise InputError("give either [[defects]] tables or defects_file, not both")
    return read_defects(defects_file, dim), f"defects_file {defects_file!r}"


def read_defects(path: str | Path, dim: int, name: str = "defects_file") -> list[dict]:
    """The defects of a CSV or JSON file (module docstring) as ``[[defects]]`` tables.

    2D: ``{"points": [[x, y], ...], "curve": "polyline"}`` (+ ``"delta"`` where the file gives one);
    3D: ``{"shape": "disk", "center", "normal", "radius"}`` or ``{"shape": "ellipse", "center", "normal",
    "axes": [a, b], "direction"}`` (+ ``"delta"``); JSON: the file's objects as they are. ``name``: the
    scene key in messages. The size is checked before the file is read (:data:`MAX_BYTES`), the counts
    before the tables are made (:data:`MAX_ROWS`, :data:`MAX_DEFECTS`)."""
    from dualfem.core.io import check_input_path

    dim = _dim(dim)
    path = Path(path)
    suffix = _suffix(path, name)
    check_input_path(path, name)
    size = os.stat(path).st_size
    label = f"{name} {str(path)!r}"
    if size > MAX_BYTES:
        raise InputError(f"{label} has {size:,} bytes; the limit is {MAX_BYTES:,} ({MAX_DEFECTS:,} defects)")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{label} is not UTF-8 text") from None
    except OSError as exc:
        raise InputError(f"{label}: cannot read it: {exc.strerror or exc}") from None
    tables = _read_json(text, label) if suffix == ".json" else _read_csv(text, dim, label)
    if not tables:
        raise InputError(f"{label} holds no defect (an uncracked body is defects = [] in the scene)")
    if len(tables) > MAX_DEFECTS:
        raise InputError(f"{label} holds {len(tables):,} defects; the limit is {MAX_DEFECTS:,}")
    return tables


def _read_json(text: str, label: str) -> list[dict]:
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise InputError(f"{label}: malformed JSON: {exc}") from None
    if not isinstance(data, list) or not all(isinstance(t, dict) for t in data):
        raise InputError(f"{label} must hold a JSON list of objects (one per defect, the keys of a "
                         f"[[defects]] table), got {type(data).__name__}")
    return data


def _forms(dim: int) -> list[tuple[str, ...]]:
    return [SEGMENT, POLYLINE] if dim == 2 else [DISK, ELLIPSE, DISK + _ELLIPSE_ONLY]


def _header(row: list[str], dim: int, label: str) -> tuple[str, ...]:
    cols = tuple(c.strip() for c in row)
    forms = _forms(dim)
    if len(set(cols)) != len(cols):
        dup = next(c for c in cols if cols.count(c) > 1)
        raise InputError(f"{label}, row 1: column {dup!r} appears twice")
    names = set(cols) - {"delta"}
    for form in forms:
        if names == set(form):
            return cols
    want = " or ".join(",".join(f) + "[,delta]" for f in forms[:2])
    raise InputError(f"{label}, row 1: the header must be {want} (a {dim}D scene; columns in any order"
                     + (", or both 3D forms mixed" if dim == 3 else "") + f"), got {','.join(cols)!r}")


def _cell(text: str, row: int, col: str, label: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{label}, row {row}, column {col!r}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise InputError(f"{label}, row {row}, column {col!r}: {text!r} is not a finite number")
    return v


def _read_csv(text: str, dim: int, label: str) -> list[dict]:
    rows = csv.reader(io.StringIO(text))
    try:
        header = next(rows)
    except StopIteration:
        raise InputError(f"{label} is empty: it needs a header row") from None
    except csv.Error as exc:
        raise InputError(f"{label}, row 1: {exc}") from None
    cols = _header(header, dim, label)
    records: list[tuple[int, dict[str, str]]] = []
    try:
        for k, row in enumerate(rows, start=2):
            if not any(c.strip() for c in row):
                continue                               # blank lines are skipped
            if len(row) != len(cols):
                raise InputError(f"{label}, row {k}: {len(row)} values for the {len(cols)} columns "
                                 f"{','.join(cols)}")
            records.append((k, {c: v.strip() for c, v in zip(cols, row, strict=True)}))
            if len(records) > MAX_ROWS:
                raise InputError(f"{label} has more than {MAX_ROWS:,} rows; the limit is {MAX_ROWS:,}")
    except csv.Error as exc:
        raise InputError(f"{label}, row {rows.line_num}: {exc}") from None
    if dim == 2:
        return _segments(records, label) if "x1" in cols else _polylines(records, label)
    return [_surface(k, r, label) for k, r in records]


def _delta(rec: dict[str, str], k: int, label: str) -> dict:
    text = rec.get("delta", "")
    return {"delta": _cell(text, k, "delta", label)} if text else {}


def _segments(records, label: str) -> list[dict]:
    out = []
    for k, rec in records:
        x1, y1, x2, y2 = (_cell(rec[c], k, c, label) for c in SEGMENT)
        out.append({"points": [[x1, y1], [x2, y2]], "curve": "polyline", **_delta(rec, k, label)})
    return out


def _polylines(records, label: str) -> list[dict]:
    out: list[dict] = []
    seen: dict[str, int] = {}
    for k, rec in records:
        ident = rec["defect"]
        if not ident:
            raise InputError(f"{label}, row {k}, column 'defect': empty; every row names its defect")
        x, y = (_cell(rec[c], k, c, label) for c in ("x", "y"))
        delta = _delta(rec, k, label)
        if out and ident == out[-1]["_id"]:
            last = out[-1]
            if delta.get("delta") != last["_delta"]:
                raise InputError(f"{label}, row {k}, column 'delta': defect {ident!r} has another delta on an "
                                 f"earlier row; give it once per defect, the same on every row (or leave it empty "
                                 f"on all of them)")
            last["points"].append([x, y])
            continue
        if ident in seen:
            raise InputError(f"{label}, row {k}, column 'defect': the rows of defect {ident!r} must be "
                             f"consecutive (it appeared before, at row {seen[ident]})")
        seen[ident] = k
        out.append({"points": [[x, y]], "curve": "polyline", "_id": ident, "_row": k,
                    "_delta": delta.get("delta"), **delta})
    for d in out:
        if len(d["points"]) < 2:
            raise InputError(f"{label}, row {d['_row']}: defect {d['_id']!r} has one point; a polyline needs "
                             f"at least two rows")
        for key in ("_id", "_row", "_delta"):
            del d[key]
    return out


def _surface(k: int, rec: dict[str, str], label: str) -> dict:
    """One 3D row: a disk (radius given) or an ellipse (a, b, dx, dy, dz given), never both."""
    has_r = bool(rec.get("radius", ""))
    ell = [c for c in _ELLIPSE_ONLY if rec.get(c, "")]
    if has_r == bool(ell) or (ell and len(ell) != len(_ELLIPSE_ONLY)):
        missing = [c for c in _ELLIPSE_ONLY if c not in ell]
        what = "both radius and " + ",".join(ell) if has_r and ell else \
            f"no value in {missing[0]!r}" if ell else "neither radius nor a,b,dx,dy,dz"
        raise InputError(f"{label}, row {k}: {what}; a row is a disk (radius) or an ellipse (a,b,dx,dy,dz)")
    c = [_cell(rec[n], k, n, label) for n in ("cx", "cy", "cz")]
    n = [_cell(rec[m], k, m, label) for m in ("nx", "ny", "nz")]
    if has_r:
        t = {"shape": "disk", "center": c, "normal": n, "radius": _cell(rec["radius"], k, "radius", label)}
    else:
        a, b, dx, dy, dz = (_cell(rec[m], k, m, label) for m in _ELLIPSE_ONLY)
        t = {"shape": "ellipse", "center": c, "normal": n, "axes": [a, b], "direction": [dx, dy, dz]}
    return {**t, **_delta(rec, k, label)}


# --------------------------------------------------------------------------------------- writing
def write_defects(path: str | Path, tables: list[dict], dim: int) -> Path:
    """Write ``[[defects]]`` tables (e.g. :func:`dualfem.problems.fractured.random_cracks`) as a defects
    file that :func:`read_defects` reads back to the same tables (numbers written exactly: Python's
    shortest round-trip repr). ``.json``: any tables. ``.csv``: 2D straight segments (``x1,y1,x2,y2``)
    or polylines (``defect,x,y``), 3D disks and ellipses (``delta`` written when any table has one);
    splines, face pressures, polygons and caps need ``.json`` (InputError saying so). Returns the path."""
    dim = _dim(dim)
    path = Path(path)
    suffix = _suffix(path, "the defects file")
    if not isinstance(tables, (list, tuple)) or not all(isinstance(t, dict) for t in tables):
        raise InputError(f"write_defects: tables must be a list of [[defects]] tables (dicts), got "
                         f"{type(tables).__name__}")
    if suffix == ".json":
        text = json.dumps([_plain(t) for t in tables], indent=1)
    else:
        text = _csv_text(tables, dim)
    path.write_text(text, encoding="utf-8")
    return path


def _plain(value: Any) -> Any:
    """numpy arrays and scalars as lists and floats (JSON)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _num(v: Any) -> str:
    return repr(float(v))


def _csv_text(tables: list[dict], dim: int) -> str:
    allowed = {"points", "curve", "delta"} if dim == 2 else \
        {"shape", "center", "normal", "radius", "axes", "direction", "delta"}
    for i, t in enumerate(tables):
        extra = sorted(set(t) - allowed)
        bad_shape = dim == 3 and t.get("shape") not in ("disk", "ellipse")
        if extra or t.get("curve", "polyline") != "polyline" or bad_shape:
            what = f"key {extra[0]!r}" if extra else \
                f"curve {t.get('curve')!r}" if dim == 2 else f"shape {t.get('shape')!r}"
            raise InputError(f"write_defects: defects[{i}] has {what}, which a CSV defects file cannot hold; "
                             f"write a .json file")
    delta = any("delta" in t for t in tables)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    d = (lambda t: [_num(t["delta"]) if "delta" in t else ""]) if delta else (lambda t: [])
    if dim == 2:
        pts = [[[_num(c) for c in p] for p in t["points"]] for t in tables]
        if all(len(p) == 2 for p in pts):
            w.writerow([*SEGMENT, *(["delta"] if delta else [])])
            for t, p in zip(tables, pts, strict=True):
                w.writerow([*p[0], *p[1], *d(t)])
        else:
            w.writerow([*POLYLINE, *(["delta"] if delta else [])])
            for k, (t, p) in enumerate(zip(tables, pts, strict=True)):
                for q in p:
                    w.writerow([k, *q, *d(t)])
        return buf.getvalue()
    shapes = {t["shape"] for t in tables}
    cols = DISK if shapes == {"disk"} else ELLIPSE if shapes == {"ellipse"} else DISK + _ELLIPSE_ONLY
    w.writerow([*cols, *(["delta"] if delta else [])])
    for t in tables:
        row = {"cx": t["center"][0], "cy": t["center"][1], "cz": t["center"][2],
               "nx": t["normal"][0], "ny": t["normal"][1], "nz": t["normal"][2]}
        if t["shape"] == "disk":
            row["radius"] = t["radius"]
        else:
            row.update(zip(_ELLIPSE_ONLY, [*t["axes"], *t["direction"]], strict=True))
        w.writerow([_num(row[c]) if c in row else "" for c in cols] + d(t))
    return buf.getvalue()
