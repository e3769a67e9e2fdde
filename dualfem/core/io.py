"""Atomic file output: a results file is either complete or absent, never half-written."""
from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from dualfem.core.errors import InputError, OutputError


def jsonable(o: Any) -> Any:
    """Plain JSON data: numpy scalars and arrays as Python numbers and lists, NaN/inf as None."""
    if isinstance(o, dict):
        return {str(k): jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return jsonable(o.tolist())
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    return o


def dumps(obj: Any) -> str:
    """JSON with NaN/inf written as null (valid JSON for every consumer), on one line."""
    import json

    return json.dumps(jsonable(obj), indent=None)


def check_output_path(path: str | Path, flag: str) -> Path:
    """Refuse, before any work, an output path that cannot be written: a directory, a path under a
    regular file, a folder without write permission. Returns the path."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{flag} {str(path)!r} is a directory; give a file name")
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f"{flag} {str(path)!r}: {str(parent)!r} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{flag} {str(path)!r}: no permission to write in {str(parent)!r}")
    try:                    # os.access says yes to root and on read-only file systems: try for real
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise InputError(f"{flag} {str(path)!r}: cannot write in {str(parent)!r}: {exc.strerror or exc}") from None
    return path


def _kind(mode: int) -> str:
    import stat

    for test, name in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a directory")):
        if test(mode):
            return name
    return "not a regular file"


def check_input_path(path: str | Path, what: str, folder: bool = False) -> Path:
    """``path`` if it names an existing regular file (``folder``: a directory); else an InputError naming
    ``what`` (e.g. "scene file"). Checked with ``stat``, never by opening: a FIFO, a device or a socket is
    refused before anything reads it (opening a FIFO blocks until a writer comes, reading a device may
    never end)."""
    import stat

    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise InputError(f"{what} {str(path)!r} does not exist") from None
    except OSError as exc:
        raise InputError(f"{what} {str(path)!r}: cannot read it: {exc.strerror or exc}") from None
    if (stat.S_ISDIR(mode) if folder else stat.S_ISREG(mode)):
        return path
    want = "a folder" if folder else "a regular file"
    raise InputError(f"{what} {str(path)!r} is {_kind(mode)}, not {want}: it is refused before reading")


#: what a results folder (of bench or stress) may hold that a command reads without being asked
RESULTS_ENTRIES = ("results.csv", "curves.csv", "sweep.json", "spec.toml", "runs.jsonl", "meta.json", "rows",
                   "refs", "curves", "records")


def check_folder_files(folder: str | Path, what: str, depth: int = 2, only: Iterable[str] | None = None) -> None:
    """Refuse (InputError naming ``what`` and the entry) a results folder holding a FIFO, a device or a
    socket in it or in its subfolders down to ``depth`` levels (rows/, refs/, curves/): commands read
    those files without asking, and opening a FIFO blocks. ``only``: the top-level names looked at (e.g.
    :data:`RESULTS_ENTRIES` when the folder is the user's own, holding a results.csv given by name).
    Checked with ``stat`` only; a folder that does not exist passes (it is created later)."""
    import stat

    keep = None if only is None else set(only)
    todo = [(Path(folder), 0)]
    while todo:
        d, level = todo.pop()
        try:
            entries = list(os.scandir(d))
        except (FileNotFoundError, NotADirectoryError):
            continue
        except OSError as exc:
            raise InputError(f"{what} {str(d)!r}: cannot list it: {exc.strerror or exc}") from None
        for e in entries:
            if level == 0 and keep is not None and e.name not in keep:
                continue
            try:
                mode = os.stat(e.path).st_mode
            except OSError:
                continue                # a dangling link: nothing to block on
            if stat.S_ISDIR(mode) and level == 0 and e.name in RESULTS_ENTRIES and "." in e.name:
                raise InputError(f"{what} {str(folder)!r} holds a folder named {e.name!r} where its file belongs: "
                                 "move it away first (nothing could be written there)")
            if stat.S_ISDIR(mode):
                if level + 1 < depth:
                    todo.append((Path(e.path), level + 1))
            elif not stat.S_ISREG(mode):
                raise InputError(f"{what} {str(folder)!r} holds {str(e.path)!r}, {_kind(mode)}, not a regular "
                                 "file: move it away first (it is refused before anything reads it)")


def refuse_overwrite(paths: Iterable[str | Path], force: bool, flag: str = "--force") -> None:
    """Before any work: InputError naming the first of ``paths`` that exists, unless ``force``
    (results of another run, or committed ones, are replaced only when asked explicitly)."""
    if force:
        return
    for path in map(Path, paths):
        if path.exists():
            raise InputError(f"{str(path)!r} exists (results of another run); give another --out, or "
                             f"{flag} to replace it")


def atomic_write(path: str | Path, write: Callable[[str], None]) -> Path:
    """Call ``write(tmp_path)`` on a temporary file next to ``path``, then rename it into place."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    except OSError as exc:              # read-only file system, no permission, a file in the way
        raise OutputError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from exc
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError):    # disk full, file size limit, permission: one clear line
            raise OutputError(f"cannot write {str(path)!r}: {exc.strerror or exc} (nothing was written to it)") from exc
        raise
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically."""
    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
    return atomic_write(path, write)


def atomic_savefig(fig, path: str | Path, **savefig_kwargs) -> Path:
    """Save a matplotlib figure atomically (PNG unless ``format`` is given)."""
    savefig_kwargs.setdefault("format", "png")
    return atomic_write(path, lambda tmp: fig.savefig(tmp, **savefig_kwargs))


def _aside_names(path: Path, tag: str):
    """``NAME.TAG-<UTC time to the second>``, then ``...-2``, ``...-3``, ...: candidates for a kept copy."""
    import time

    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    base = f"{path.name}.{tag}-{stamp}"
    yield path.with_name(base)
    for i in range(2, 100000):
        yield path.with_name(f"{base}-{i}")


def move_aside(path: str | Path, tag: str) -> Path:
    """Rename ``path`` to a new, unique ``NAME.TAG-<time>[-k]`` beside it; never replaces an existing
    file (two in one second get two names: the name is reserved by a hard link, which fails if taken)."""
    path = Path(path)
    for dest in _aside_names(path, tag):
        try:
            os.link(path, dest)
        except FileExistsError:
            continue
        except OSError:                  # no hard links here: reserve the name, then replace it
            try:
                os.close(os.open(dest, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
            except FileExistsError:
                continue
            os.replace(path, dest)
            return dest
        os.unlink(path)
        return dest
    raise OutputError(f"cannot move {str(path)!r} aside: no free name")  # pragma: no cover


def write_aside(path: str | Path, tag: str, text: str) -> Path:
    """Write ``text`` to a new, unique ``NAME.TAG-<time>[-k]`` beside ``path`` (never replacing a file)."""
    path = Path(path)
    for dest in _aside_names(path, tag):
        try:
            with open(dest, "x", encoding="utf-8") as fh:
                fh.write(text)
        except FileExistsError:
            continue
        return dest
    raise OutputError(f"cannot keep a copy of {str(path)!r}: no free name")  # pragma: no cover


def backup(path: str | Path, tag: str = "bak") -> Path | None:
    """A copy of ``path`` (if it exists) under a new, unique name beside it (``NAME.TAG-<time>[-k]``),
    complete or absent (copied to a temporary file, then linked to a name that must be free); never
    replaces an existing backup. Returns the backup's path."""
    import shutil

    path = Path(path)
    if not path.is_file():
        return None
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as out, open(path, "rb") as src:
            shutil.copyfileobj(src, out)
        os.chmod(tmp, 0o644)
        for dest in _aside_names(path, tag):
            try:
                os.link(tmp, dest)
            except FileExistsError:
                continue
            return dest
        raise OutputError(f"cannot back up {str(path)!r}: no free name")  # pragma: no cover
    except OSError as exc:
        raise OutputError(f"cannot back up {str(path)!r}: {exc.strerror or exc}") from exc
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
