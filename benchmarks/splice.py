#!/usr/bin/env python3
"""Build spliced performances with exact boundaries from real single-behaviour takes.

    python3 benchmarks/splice.py ../shared/data/cmu_single /tmp/spliced --n 20 --kind both
    rtseg evaluate /tmp/spliced --group spliced

SRC is laid out like ``../shared/data/cmu_single`` (index.tsv, bvh/, amc/).  OUT gets
``same_NNN.npz`` / ``mixed_NNN.npz`` (rtseg takes with per-frame behaviour labels and the
cross-fade spans as transition ranges) and ``index.tsv`` (one row per segment).  The same
--seed gives byte-identical files.  The rules are in ``rtseg.evaluation.splice`` and docs/splice.md.
Exit status 2 on bad input (one line on stderr).
"""

from __future__ import annotations

import argparse
import logging
import sys
import time

from rtseg.evaluation.splice import KINDS, SpliceConfig, generate, read_source_index


def mixed_possible(src: str) -> bool:
    """True when some format of ``src`` holds takes of two or more people."""
    people: dict[str, set[str]] = {}
    for r in read_source_index(src):
        people.setdefault(r.fmt, set()).add(r.subject)
    return any(len(p) >= 2 for p in people.values())


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("src", help="source folder laid out like ../shared/data/cmu_single")
    p.add_argument("out", help="output folder (created)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--n", type=int, default=20, help="performances per kind (default 20)")
    p.add_argument("--kind", choices=[*KINDS, "both"], default="both",
                   help="same: one person; mixed: two or more people of one format; both")
    p.add_argument("--force", action="store_true",
                   help="remove other .npz files in OUT instead of refusing")
    p.add_argument("-v", "--verbose", action="store_true", help="log trims and unused pools")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    if args.n < 1:
        p.error("--n must be at least 1")
    kinds = KINDS if args.kind == "both" else (args.kind,)
    t0 = time.perf_counter()
    try:
        if args.kind == "both" and not mixed_possible(args.src):
            kinds = ("same",)
        perfs = generate(args.src, args.out, seed=args.seed, n=args.n, kinds=kinds,
                         cfg=SpliceConfig(), force=args.force)
    except (OSError, ValueError) as exc:
        print(f"splice: error: {exc}", file=sys.stderr)
        return 2
    if args.kind == "both" and kinds == ("same",):   # said once there is something to splice
        print(f"splice: {args.src} holds one person per format: same-person "
              f"performances only", file=sys.stderr)
    for perf in perfs:
        sp = perf.take.meta["splice"]
        print(f"{perf.name}\t{sp['format']}\t{','.join(sp['subjects'])}\t"
              f"{perf.take.n_frames / perf.take.frame_rate:6.1f} s\t{len(perf.segments)} segments\t"
              + " ".join(s["behaviour"] for s in perf.segments))
    print(f"splice: {len(perfs)} performance(s) in {args.out}, "
          f"{time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
