"""A one-line progress bar for steps of known count (``evaluate``, library reports): stderr,
rewritten in place on a terminal, one plain line per step otherwise."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """A one-line progress bar on a terminal (stderr); one plain line per step otherwise."""

    def __init__(self, total: int, stream: TextIO | None = None, enabled: bool = True,
                 width: int = 24) -> None:
        self.total = max(total, 1)
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.width = width
        self.done = 0
        self.t0 = time.monotonic()
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def step(self, label: str) -> None:
        """Announce the step about to run (``label``), counting the previous one as done."""
        if not self.enabled:
            return
        n = self.done
        fill = int(self.width * n / self.total)
        bar = "#" * fill + "-" * (self.width - fill)
        text = f"evaluate [{bar}] {n}/{self.total} {time.monotonic() - self.t0:5.1f}s {label}"
        if self.tty:
            self.stream.write("\r" + text[:100].ljust(100))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()
        self.done += 1

    def close(self) -> None:
        if not self.enabled:
            return
        text = (f"evaluate [{'#' * self.width}] {self.total}/{self.total} "
                f"{time.monotonic() - self.t0:5.1f}s done")
        self.stream.write(("\r" + text.ljust(100) + "\n") if self.tty else text + "\n")
        self.stream.flush()
