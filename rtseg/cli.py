"""The ``rtseg`` console command.  Each sub-command is a module in ``rtseg.commands`` with
``register(subparsers)`` adding its parser and setting ``func(args) -> int``.

Exit status: 0 success, 2 a usage, configuration or input error (bad option, missing or
unreadable file, bad source URL), reported as ONE line on stderr
(``rtseg live: error: ...``) - never a traceback; 1 an unexpected internal error (one line
too; ``-vv`` shows the traceback); 130 Ctrl-C.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import math
import sys
from typing import NoReturn

COMMANDS = ["segment", "evaluate", "plot", "simulate", "live", "demo", "learn", "calibrate"]


#: exit status of a usage, configuration or input error
EXIT_USAGE = 2


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line: ``PROG: error: MESSAGE (see
    PROG --help)``, exit status 2.  Sub-command parsers are of this class too."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (seconds, Hz, factors)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return v


def params_file(text: str) -> str:
    """argparse type of ``--params``: a parameter file or a shipped one's name, not empty
    (an empty name would read the current folder, or be taken for no file at all)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a parameter file (TOML or JSON) or a "
                                         "shipped one's name such as 'fast', got ''")
    return text


def error_text(exc: BaseException) -> str:
    """One line describing ``exc`` (a KeyError's message without its quotes): runs of
    white space become one space and other unprintable characters (a path may hold any)
    are escaped, so the message is one line on every terminal and to ``str.splitlines``."""
    if isinstance(exc, KeyError) and len(exc.args) == 1 and isinstance(exc.args[0], str):
        text = exc.args[0]
    else:
        text = str(exc) or type(exc).__name__
    return one_line(text)


def one_line(text: str) -> str:
    """``text`` on one printable line (see ``error_text``)."""
    text = " ".join(text.split())
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii")
                   for c in text)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="rtseg", description="Cut motion capture into distinct behaviours, live or offline.")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"rtseg.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"rtseg.commands.{name}":
                continue  # command not built yet
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        parser = build_parser()   # imports every command: Ctrl-C may come meanwhile
        args = parser.parse_args(argv)
    except SystemExit as exc:     # usage error (one line already printed) or --help
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    except KeyboardInterrupt:
        return 130
    logging.basicConfig(
        level=logging.WARNING - 10 * min(args.verbose, 2),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:       # stdout closed early (`rtseg ... | head`): stop quietly
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except (OSError, ValueError, KeyError, EOFError, MemoryError) as exc:
        print(f"rtseg {args.command}: error: {error_text(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except Exception as exc:
        from rtseg.drivers.base import SourceError
        if isinstance(exc, SourceError):          # a source that cannot be opened
            print(f"rtseg {args.command}: error: {error_text(exc)}", file=sys.stderr)
            return EXIT_USAGE
        # a bug: one line, the traceback only with -vv
        logging.getLogger("rtseg").debug("internal error", exc_info=True)
        print(f"rtseg {args.command}: internal error: {type(exc).__name__}: "
              f"{error_text(exc)} (rerun with -vv for the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
