"""Progress of a long experiment on stderr: a bar on a terminal, one plain line per item otherwise."""
from __future__ import annotations

import sys
import time


class Progress:
    """A bar on a terminal, one plain line per finished item otherwise (CI logs)."""

    def __init__(self, total: int, title: str, stream=None, tty: bool | None = None):
        self.total, self.done, self.title = total, 0, title
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self.t0 = time.monotonic()

    def update(self, text: str) -> None:
        self.done += 1
        el = time.monotonic() - self.t0
        eta = el / self.done * (self.total - self.done) if self.done else 0.0
        if self.tty:
            w = 30
            k = int(w * self.done / max(self.total, 1))
            line = f"\r{self.title} [{'#' * k}{'.' * (w - k)}] {self.done}/{self.total} " \
                   f"{el:5.0f}s eta {eta:5.0f}s {text[:60]:60s}"
            self.stream.write(line)
            if self.done == self.total:
                self.stream.write("\n")
        else:
            self.stream.write(f"{self.title} [{self.done}/{self.total}] {text} (elapsed {el:.0f} s)\n")
        self.stream.flush()

