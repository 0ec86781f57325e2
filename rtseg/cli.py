"""The ``rtseg`` console command.  Each sub-command is a module in ``rtseg.commands`` with
``register(subparsers)`` adding its parser and setting ``func(args) -> int``."""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

COMMANDS = ["segment", "evaluate", "plot", "simulate", "live", "demo"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
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
    parser = build_parser()
    args = parser.parse_args(argv)
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
    except (OSError, ValueError, KeyError, EOFError) as exc:
        print(f"rtseg {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
