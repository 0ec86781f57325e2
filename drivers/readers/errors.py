"""The one exception every take reader raises for malformed input."""

from __future__ import annotations

from pathlib import Path


class ReaderError(ValueError):
    """A take file could not be read.

    The message always names the file and, where the problem is on one line, the 1-based
    line number: ``"86_01.amc:1234: bone 'lfemur' has 2 values, expected 3"``.
    ``path``, ``line`` and ``problem`` are kept as attributes for programs.
    """

    def __init__(self, path: str | Path, problem: str, line: int | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.problem = problem
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {problem}")
