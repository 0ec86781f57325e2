"""The one exception every take reader raises for malformed input, and the text loader
and number test the line-oriented readers share."""

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


def is_number(token: str) -> bool:
    """Whether ``float(token)`` parses (to name the bad token in a ``ReaderError``)."""
    try:
        float(token)
        return True
    except ValueError:
        return False


def read_text_lines(path: Path) -> list[str]:
    """The lines of a text take file (UTF-8 with or without a byte-order mark, else
    Latin-1; CRLF, CR and LF alike).

    A missing file or a directory raises ``ReaderError`` naming the path.
    """
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ReaderError(path, "file not found") from None
    except IsADirectoryError:
        raise ReaderError(path, "is a directory, not a file") from None
    except PermissionError:
        raise ReaderError(path, "permission denied") from None
    except OSError as exc:
        raise ReaderError(path, f"cannot read ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8-sig")   # drops a leading UTF-8 byte-order mark
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return text.splitlines()


def ends_mid_line(path: Path) -> bool:
    """Whether the file's last byte is not a line break (it was cut inside a line)."""
    try:
        with open(path, "rb") as fh:
            fh.seek(-1, 2)
            return fh.read(1) not in (b"\n", b"\r")
    except OSError:
        return False
