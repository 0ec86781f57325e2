#!/usr/bin/env python3
"""Accuracy of every detector on a labelled data folder (laid out like ../shared/data).

    python3 benchmarks/accuracy.py ../shared/data            # table, full-rotation takes
    python3 benchmarks/accuracy.py ../shared/data --json     # JSON, as `rtseg evaluate --json`
    python3 benchmarks/accuracy.py DATA --group all          # also the tsseg4d takes

A thin wrapper over ``rtseg.commands.evaluate``: same take discovery, matching and pooling
(counts summed over takes, then divided).  Prints the wall time of the run on stderr.
Exit status 1 when a take could not be read or segmented.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time

from rtseg.commands.evaluate import add_evaluate_arguments, evaluate_dir, format_table
from rtseg.commands.segment import methods_of, params_by_method


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_evaluate_arguments(p)
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    methods = methods_of(args.method)
    t0 = time.perf_counter()
    try:
        report = evaluate_dir(args.data_dir, methods, args.group,
                              params_by_method(args.params, methods),
                              progress=not args.no_progress, profile=args.profile)
    except (OSError, ValueError, KeyError) as exc:
        print(f"accuracy: error: {exc}", file=sys.stderr)
        return 1
    elapsed = time.perf_counter() - t0
    if args.json:
        print(json.dumps(report.as_dict(), indent=2, allow_nan=False))
    else:
        print(format_table(report), end="")
    print(f"accuracy: {len(methods)} method(s), wall time {elapsed:.1f} s", file=sys.stderr)
    return 1 if report.errors else 0


if __name__ == "__main__":
    sys.exit(main())
