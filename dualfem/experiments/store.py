"""The results folder of a sweep: one atomic JSON file per row, a merged ``results.csv``, references.

``rows/<run_id>.json`` (a row file is complete or absent), ``results.csv`` (rewritten
atomically), ``refs/<scene_key>.npz`` (certified reference solutions); with ``curves = true``,
``curves/<run_id>.json`` and ``curves.csv`` (:mod:`dualfem.experiments.curves`). The results file itself
is written and read by :mod:`dualfem.experiments.results_csv` (its names stay importable from here).
"""
from __future__ import annotations

import contextlib
import json
import sys
import time
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from dualfem.core.errors import InputError, OutputError
from dualfem.core.io import (
    RESULTS_ENTRIES,
    atomic_write,
    atomic_write_text,
    check_folder_files,
    move_aside,
)
from dualfem.experiments.results_csv import (  # noqa: F401 (their earlier home: the old import paths keep working)
    REPORT_COLUMNS,
    TEXT_COLUMNS,
    _lines,
    check_report_input,
    read_results,
    read_results_checked,
    write_csv,
    write_parquet,
)
from dualfem.experiments.row import Row

#: statuses of a run that are final (a resumed sweep does not redo them, ``--retry-failed`` redoes
#: those other than solved/inaccurate); ``skipped`` rows are cheap and redone, so that a solver
#: registered later gets its runs and a gate (:func:`dualfem.experiments.bench.run_tasks`) decides again.
FINAL_STATUSES = {"solved", "inaccurate", "max_iter", "time_limit", "stagnation", "numerical_error",
                  "infeasible", "error", "crashed"}


class ResultStore:
    """``rows/<run_id>.json`` (one atomic file per row), ``results.csv`` (atomic merge), ``refs/``.

    Nothing is lost: rows that exist only in ``results.csv`` (``rows/`` is not committed) are
    kept as finished rows; a corrupt row or reference file is moved aside (``*.corrupt``) with a
    warning and its run redone; a lock file (``.lock``) refuses a second sweep on the same folder;
    a folder belongs to one spec (:meth:`claim`).
    """

    def __init__(self, out: str | Path, warn: Callable[[str], None] | None = None):
        self.out = Path(out)
        self.warn = warn or (lambda msg: print(f"dualfem bench: warning: {msg}", file=sys.stderr))
        self.rows_dir = self.out / "rows"
        self.refs_dir = self.out / "refs"
        self._lock = None

    def open(self) -> ResultStore:
        """Create the folder, take its lock, clear interrupted temporary files, read every row. A folder
        holding a FIFO or a device (:func:`~dualfem.core.io.check_folder_files`) is refused first."""
        check_folder_files(self.out, "--out", only=RESULTS_ENTRIES)
        self.rows_dir.mkdir(parents=True, exist_ok=True)
        self.refs_dir.mkdir(parents=True, exist_ok=True)
        self._take_lock()
        # temporary files of writes interrupted by a kill (atomic_write names them ".NAME.*"):
        # the result they were meant to become is absent, so the run is simply redone
        stale = [p for d in (self.rows_dir, self.refs_dir) for p in d.glob(".*")]
        stale += [p for n in ("results.csv", "curves.csv", "sweep.json", "spec.toml") for p in self.out.glob(f".{n}.*")]
        for p in stale:
            if p.is_file():
                p.unlink()
        self.rows: dict[str, dict] = {}
        for p in sorted(self.rows_dir.glob("[!.]*.json")):
            try:
                r = json.loads(p.read_text(encoding="utf-8"))
                self.rows[r["run_id"]] = r
            except (OSError, ValueError, KeyError, TypeError):
                self.set_aside(p, "unreadable row file; its run is redone unless results.csv holds it")
        csv_path = self.out / "results.csv"
        bad: list = []
        if csv_path.is_file():
            try:
                kept, bad = read_results_checked(csv_path)
            except InputError as exc:
                kept, bad = [], []
                self.set_aside(csv_path, f"unreadable results.csv ({exc})")
            for r in kept:
                rid = r["run_id"]
                if rid not in self.rows:
                    # a row kept only in the (committed) CSV: give it its own file again
                    self.rows[rid] = Row.from_dict(r).to_dict()
                    atomic_write_text(self.rows_dir / f"{rid}.json", json.dumps(self.rows[rid], sort_keys=True))
            if bad:
                # the readable rows are in rows/ now; keep the file as it was (with its damaged lines)
                dest = move_aside(csv_path, "corrupt")
                self.warn(f"{len(bad)} unreadable line(s) of results.csv ({_lines(bad)}: a cut or damaged write?): "
                          f"the file as it was is kept as {str(dest)!r}; its {len(kept)} readable row(s) are kept, "
                          f"the runs of the unreadable lines are redone")
                write_csv(csv_path, list(self.rows.values()))     # at once: every readable row
        self._last_csv = 0.0
        self.keep: Callable[[dict], bool] | None = None
        self.curves = None     # a dualfem.experiments.curves.CurveStore, when the sweep records curves
        return self

    def _take_lock(self) -> None:
        self._lock = lock_folder(self.out)

    def close(self) -> None:
        """Release the folder's lock."""
        if self._lock is not None:
            self._lock.close()
            self._lock = None

    def set_aside(self, p: Path, why: str) -> None:
        try:
            dest = move_aside(p, "corrupt")         # a new name: never replaces an earlier one
            self.warn(f"{why}: moved {str(p)!r} to {str(dest)!r}")
        except (OSError, OutputError):
            self.warn(f"{why}: {str(p)!r} ignored")

    def claim(self, name: str, text: str, force: bool = False, same_name: bool = False) -> None:
        """Refuse a folder that holds the results of another spec (unless ``force``).

        Another spec is one of another name, or of the same name with other contents (an edited
        spec, or another spec that happens to share the name: its rows would be mixed with this
        one's); ``same_name`` accepts the latter (a stress grid: any grid adds its rows to a grid
        folder). Nothing is written here (:func:`dualfem.experiments.bench.open_store` keeps the
        replaced spec.toml as a backup).
        """
        prev = self.out / "spec.toml"
        if force or not prev.is_file():
            return
        old = prev.read_text(encoding="utf-8", errors="replace")
        if same_spec(old, text):
            return
        if _spec_name(old) == name:
            if same_name:
                return
            raise InputError(f"--out {str(self.out)!r} holds the results of a spec named {name!r} with other "
                             f"contents (its spec.toml differs from this one); choose another --out, or pass "
                             f"--force to add this spec's rows to it (nothing is dropped, the old spec.toml is kept)")
        raise InputError(f"--out {str(self.out)!r} holds the results of another spec "
                         f"({_spec_name(old) or 'unnamed'!r}, not {name!r}); choose another --out, "
                         f"or pass --force to add this spec's rows to it")

    def on_disk(self) -> str:
        """What the folder holds now, for a message after a failed write: "rows/ (3 runs), refs/ (1), ...";
        "nothing" when it holds none of these."""
        parts = []
        for d, word in ((self.rows_dir, "runs"), (self.refs_dir, "references")):
            n = sum(1 for _ in d.glob("[!.]*")) if d.is_dir() else 0
            if n:
                parts.append(f"{d.name}/ ({n} {word})")
        parts += [n for n in ("spec.toml", "sweep.json", "meta.json", "results.csv", "curves.csv")
                  if (self.out / n).is_file()]
        return ", ".join(parts) or "nothing"

    @contextlib.contextmanager
    def accounted(self):
        """Re-raise a failed write (:class:`OutputError`: disk full, file size limit, a read-only file) with
        what the folder already holds (:meth:`on_disk`), which is kept: "nothing was written" only when true."""
        try:
            yield self
        except OutputError as exc:
            raise self.accounted_error(exc) from exc

    def accounted_error(self, exc: OutputError) -> OutputError:
        """``exc`` with what the folder already holds (see :meth:`accounted`)."""
        return OutputError(f"{exc}; already in {str(self.out)!r} and kept: {self.on_disk()} (rerun with "
                           f"--resume once it can be written: finished runs are not redone)")

    def done(self, run_id: str) -> bool:
        r = self.rows.get(run_id)
        return r is not None and r.get("status") in FINAL_STATUSES

    def add(self, row: Row | dict) -> None:
        """Write one row (its own atomic file) and, at most every 5 s, results.csv."""
        clean = (row if isinstance(row, Row) else Row.from_dict(row)).to_dict()
        atomic_write_text(self.rows_dir / f"{row['run_id']}.json", json.dumps(clean, sort_keys=True))
        self.rows[row["run_id"]] = clean
        if time.monotonic() - self._last_csv > 5.0:
            self.write_csv()

    def write_csv(self) -> Path:
        """results.csv of the rows of the current spec (rows of runs no longer in it stay in rows/),
        and results.parquet beside it when pandas and pyarrow are installed; curves.csv first (its
        curves are those of rows in the store: :mod:`dualfem.experiments.curves`), when recorded."""
        self._last_csv = time.monotonic()
        if self.curves is not None:
            self.curves.write_csv(self.keep)
        rows = list(self.rows.values())
        if self.keep is not None:
            rows = [r for r in rows if self.keep(r)]
        path = write_csv(self.out / "results.csv", rows)
        write_parquet(self.out / "results.parquet", rows)
        return path

    # ------------------------------------------------------------- references
    def ref_path(self, scene_key: str) -> Path:
        return self.refs_dir / f"{scene_key}.npz"

    def load_ref(self, scene_key: str) -> dict | None:
        """The cached reference of a scene, or None (absent; unreadable or failing its content hash:
        moved aside under a new name with a warning, and recomputed). The sweep checks it against
        the scene's QP before grading (:func:`dualfem.experiments.bench.check_reference`)."""
        p = self.ref_path(scene_key)
        if not p.exists():
            return None
        try:
            with np.load(p, allow_pickle=False) as d:
                ref = {"x": np.asarray(d["x"], dtype=float), "multipliers": np.asarray(d["multipliers"], dtype=float),
                       "qp_key": str(d["qp_key"]), "solver": str(d["solver"]), "kkt": float(d["kkt"]),
                       "bound": float(d["bound"]) if "bound" in d else None,
                       "params": str(d["params"]) if "params" in d else "{}",
                       "sha256": str(d["sha256"]) if "sha256" in d else None}
        except (OSError, ValueError, KeyError, EOFError, TypeError, zipfile.BadZipFile):
            self.set_aside(p, "unreadable reference file; the reference is recomputed")
            return None
        if ref["sha256"] != ref_hash(ref):
            why = "no content hash (written by an earlier version)" if ref["sha256"] is None else \
                "its content does not match its hash (changed after it was written)"
            self.set_aside(p, f"reference file {why}; the reference is recomputed")
            return None
        return ref

    def save_ref(self, scene_key: str, payload: dict) -> None:
        """Cache a certified reference (atomically, with the hash of its content); a file it replaces
        (one that failed its check) is moved aside first, never overwritten."""
        p = self.ref_path(scene_key)
        if p.exists():
            self.set_aside(p, "replaced reference file")
        digest = ref_hash(payload)

        def write(tmp):
            with open(tmp, "wb") as fh:
                np.savez(fh, x=payload["x"], multipliers=payload["multipliers"], qp_key=np.array(payload["qp_key"]),
                         solver=np.array(payload["solver"]), kkt=np.array(payload["kkt"]),
                         bound=np.array(np.nan if payload.get("bound") is None else float(payload["bound"])),
                         params=np.array(payload["params"]), sha256=np.array(digest))
        atomic_write(p, write)


def ref_hash(ref: dict) -> str:
    """SHA-256 of a reference's content (solution, multipliers, QP key, solver, KKT error, bound, params)."""
    import hashlib

    h = hashlib.sha256()
    for k in ("x", "multipliers"):
        a = np.ascontiguousarray(np.asarray(ref[k], dtype=float))
        h.update(repr(a.shape).encode() + a.tobytes())
    bound = ref.get("bound")
    bound = float("nan") if bound is None else float(bound)
    for v in (ref["qp_key"], ref["solver"], repr(float(ref["kkt"])), repr(bound), str(ref.get("params", "{}"))):
        h.update(str(v).encode() + b"\0")
    return h.hexdigest()


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's bytes (cached per process by path, size, modification time and inode)."""
    import hashlib

    path = Path(path)
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns, st.st_ino)
    if key not in _DIGESTS:
        with open(path, "rb") as fh:
            _DIGESTS[key] = hashlib.file_digest(fh, "sha256").hexdigest()
    return _DIGESTS[key]


_DIGESTS: dict[tuple, str] = {}


def _is_file(v: Any) -> bool:
    try:
        return isinstance(v, str) and bool(v) and "\0" not in v and Path(v).is_file()
    except (OSError, ValueError):
        return False


def content_ident(scene: str, params: dict) -> dict | None:
    """What a scene's cached rows and reference are keyed by, when it reads files: the scene name and
    every parameter value that names a file (a QP file, a scene file, anything a problem reads) replaced
    by ``{"sha256": ...}`` of the file's content, not its name. A changed file is another scene (its
    runs are redone; the rows of the old content stay in ``rows/``); the same content under another
    name or path is the same scene. None when the scene reads no file (its key is its name and
    parameters, as before)."""
    named = [v for v in (scene, *params.values()) if _is_file(v)]
    if not named:
        return None

    def ident(v: Any) -> Any:
        return {"sha256": file_digest(v)} if _is_file(v) else v

    return {"scene": ident(scene), "params": {k: ident(v) for k, v in params.items()}}


def current_content(scenes: list, rows: dict[str, dict], warn: Callable[[str], None] | None = None
                    ) -> Callable[[dict], bool]:
    """``keep(row)`` for results.csv: False for a row of a scene of this sweep that reads files
    (``scenes``: :class:`dualfem.experiments.tasks.SceneSpec`, same ``scene`` name) made with another
    content of them (another ``scene_key``): the file changed since, and its rows would be read as the
    new content's. Such rows stay in ``rows/`` (nothing is deleted); ``warn`` says how many."""
    current: dict[str, set] = {}
    for sc in scenes:
        if sc.content is not None:
            current.setdefault(sc.scene, set()).add(sc.key)

    def keep(r: dict) -> bool:
        keys = current.get(str(r.get("scene")))
        return keys is None or r.get("scene_key") in keys

    old = [r for r in rows.values() if not keep(r)]
    if old and warn is not None:
        names = sorted({str(r.get("scene")) for r in old})
        warn(f"{len(old)} row(s) of {', '.join(map(repr, names[:3]))}{' ...' if len(names) > 3 else ''} were made "
             f"with another content of the file(s) (changed since): they stay in rows/, not in results.csv, and "
             f"the runs of the current content are made")
    return keep


def lock_folder(out: Path):
    """Take the exclusive lock of a results folder (released when the returned file is closed)."""
    import fcntl

    fh = open(out / ".lock", "a+")
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.close()
        raise InputError(f"--out {str(out)!r} is in use by another running sweep (lock file "
                         f"{str(out / '.lock')!r}); wait for it or choose another --out") from None
    return fh


def safe_name(name: str, what: str = "spec name") -> str:
    """``name`` if it is a safe folder name (letters, digits, ``._-``; no separators, no ``..``)."""
    import re

    if not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9._-]{0,63}", name or "") or ".." in name:
        raise InputError(f"{what} {name!r} cannot name a results folder: use 1-64 letters, digits, '.', '_' or "
                         f"'-' (no path separators, no '..', not starting with '.')")
    return name


#: where commands write when no --out is given: a user results folder, never the committed results
USER_RESULTS = Path("dualfem-results")


def default_out(kind: str, name: str) -> Path:
    """``dualfem-results/<kind>/<name>`` in the working directory (name checked by :func:`safe_name`)."""
    return USER_RESULTS / kind / safe_name(name)


def same_spec(a: str, b: str) -> bool:
    """Whether two spec texts define the same sweep (parsed TOML or JSON equal; else the same text)."""
    import tomllib

    if a.strip() == b.strip():
        return True
    for parse in (tomllib.loads, json.loads):
        try:
            return parse(a) == parse(b)
        except ValueError:
            continue
    return False


def _spec_name(text: str) -> str | None:
    import tomllib

    try:
        v = tomllib.loads(text).get("name")
    except (tomllib.TOMLDecodeError, AttributeError):
        return None
    return str(v) if v is not None else None
