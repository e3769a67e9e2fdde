"""Silence C libraries that write to the process's stdout (OSQP prints some notices even with
``verbose=False``), so that ``--json`` output stays exactly one JSON object."""
from __future__ import annotations

import contextlib
import os
import sys


@contextlib.contextmanager
def c_stdout_to_stderr():
    """Redirect file descriptor 1 to stderr for the duration of the block."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # pytest capture or no real stdout
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        os.dup2(sys.stderr.fileno(), fd)
        yield
    finally:
        try:
            sys.stdout.flush()
        except Exception:
            pass
        os.dup2(saved, fd)
        os.close(saved)


def _fd(stream) -> int | None:
    try:
        return stream.fileno()
    except (AttributeError, OSError, ValueError):  # None, closed, or not a real file (a test's capture)
        return None


@contextlib.contextmanager
def plugin_output():
    """Contain what plugin code writes to the standard output: Python's ``print`` and writes to file
    descriptor 1 by C libraries go to stderr for the duration of the block, so that a plugin printing
    at import time, in ``__init__``, ``setup`` or ``solve`` cannot corrupt ``--json`` (exactly one JSON
    object on stdout). Safe to nest; does nothing at the descriptor level where stdout or stderr is not
    a real file."""
    out, err = sys.stdout, sys.stderr
    fd_out, fd_err = _fd(out), _fd(err)
    saved = None
    if fd_out is not None and fd_err is not None and fd_out != fd_err:
        try:
            out.flush()
            saved = os.dup(fd_out)
            err.flush()
            os.dup2(fd_err, fd_out)
        except OSError:
            if saved is not None:
                os.close(saved)
            saved = None
    try:
        with contextlib.redirect_stdout(err if err is not None else open(os.devnull, "w")):  # noqa: SIM115
            yield
    finally:
        if saved is not None and fd_out is not None:
            for stream in (out, err):          # what a plugin wrote to sys.__stdout__ goes to stderr too
                try:
                    stream.flush()
                except Exception:  # noqa: BLE001 - restoring stdout matters more
                    pass
            os.dup2(saved, fd_out)
            os.close(saved)
