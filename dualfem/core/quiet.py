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
