"""Progress of one long command on stderr: each stage with its time, once the command has run
longer than :data:`QUIET_FOR` seconds (a quick solve prints nothing); ``--quiet`` silences it."""
from __future__ import annotations

import sys
import time

#: stages are shown once the command has been running this long (seconds)
QUIET_FOR = 2.0


class Stages:
    """Collects ``(stage, seconds)``; prints them on stderr once the command is slow."""

    def __init__(self, command: str, quiet: bool = False) -> None:
        self.command, self.quiet = command, quiet
        self.t0 = time.perf_counter()
        self.pending: list[str] = []
        self.shown = False

    def __call__(self, stage: str, seconds: float) -> None:
        self.pending.append(f"dualfem {self.command}: {stage} {seconds:.2f} s")
        if not self.quiet and (self.shown or time.perf_counter() - self.t0 > QUIET_FOR):
            self.shown = True
            for line in self.pending:
                print(line, file=sys.stderr, flush=True)
            self.pending.clear()
