"""Silence C libraries that write to the process's stdout (OSQP prints some notices even with
``verbose=False``, HiGHS a copyright banner on every solve), so that ``--json`` output stays exactly
one JSON object and the user's terminal shows dualfem's own lines only.

What the third-party libraries wrapped by dualfem's own solvers write to file descriptor 1 while they
run is dropped unless verbose output was asked for (``--verbose`` on the command line, or the
environment variable ``DUALFEM_VERBOSE`` set to anything but "" or "0"; inherited by a sweep's worker
processes); a third-party *plugin*'s output is never dropped: it goes to stderr."""
from __future__ import annotations

import contextlib
import os
import sys

#: the environment variable that asks for the third-party libraries' own output
VERBOSE_ENV = "DUALFEM_VERBOSE"


def verbose() -> bool:
    """Whether the third-party libraries' own output (banners, iteration logs) reaches stderr."""
    return os.environ.get(VERBOSE_ENV, "") not in ("", "0")


def set_verbose(flag: bool) -> None:
    """Ask for (True) or drop (False) the third-party libraries' own output, in this process and the
    worker processes it starts (through :data:`VERBOSE_ENV`)."""
    if flag:
        os.environ[VERBOSE_ENV] = "1"
    else:
        os.environ.pop(VERBOSE_ENV, None)


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
def plugin_output(drop_c_output: bool = False):
    """Contain what plugin code writes to the standard output: Python's ``print`` and writes to file
    descriptor 1 by C libraries go to stderr for the duration of the block, so that a plugin printing
    at import time, in ``__init__``, ``setup`` or ``solve`` cannot corrupt ``--json`` (exactly one JSON
    object on stdout). ``drop_c_output``: the writes to file descriptor 1 (C libraries' banners) go to
    the null device instead, unless :func:`verbose`. Safe to nest; does nothing at the descriptor
    level where stdout or stderr is not a real file."""
    out, err = sys.stdout, sys.stderr
    fd_out, fd_err = _fd(out), _fd(err)
    saved = None
    if fd_out is not None and fd_err is not None and fd_out != fd_err:
        try:
            out.flush()
            saved = os.dup(fd_out)
            err.flush()
            if drop_c_output and not verbose():
                null = os.open(os.devnull, os.O_WRONLY)
                try:
                    os.dup2(null, fd_out)
                finally:
                    os.close(null)
            else:
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
