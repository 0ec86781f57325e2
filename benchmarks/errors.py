#!/usr/bin/env python3
"""Where the live detector's cuts go wrong: every missed transition with its cause and every
false cut with where it falls, per source and pooled, on the performances of
``benchmarks/lopo.py``.

    python3 benchmarks/errors.py ../shared/data --seeds 0 1 2
    python3 benchmarks/errors.py ../shared/data --params fast --json

DIR is laid out like ``../shared/data`` (or one source folder), as for ``lopo.py``, whose
performances (cmu takes and spliced ones, cached under ``--cache``) and fed feature rows
this uses.  The contrast detector (shipped parameters, or ``--params``) runs on each
performance's rows, keeping its profile, its gate's decisions and its relative floor's
refusals; ``rtseg.evaluation.errors.attribute`` names the cause of each miss (gate
dropped, floor refused, below threshold, cut outside, no maximum sent; for a cut outside,
whether the motion between it and the range moves like the behaviour labelled there or
like the other side of the cut, ``span_resemblance``) and sorts each false cut as near a
transition or inside a segment.  Printed: per source the counts by
cause and kind, the behaviour pairs missed most and the behaviours holding the false cuts
inside segments; ``--json``: the same and every miss and false cut of every performance.
Exit status 2 on a missing folder (one line on stderr).
"""

from __future__ import annotations

import argparse
import json
import os
import sys

if __name__ == "__main__":
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")      # as lopo.py: 48 x 48 algebra, one thread


import lopo
from rtseg.evaluation.errors import Errors, attribute, span_resemblance, tally_errors
from rtseg.evaluation.online import to_take_frames
from rtseg.evaluation.scoring import pooled_tally, tally


def performance_errors(case: lopo.Case, params: dict) -> tuple[Errors, tuple]:
    """The errors of the contrast detector with ``params`` on one performance's fed rows,
    and its tally row (``rtseg.evaluation.scoring.tally``)."""
    det, cuts = lopo.detect(case, params, keep_trace=True)
    last = len(case.index) - 1
    take = lambda f: int(case.index[min(max(int(f), 0), last)])   # noqa: E731
    pairs = to_take_frames(cuts, case.index)
    errs = attribute(
        [c for c, _ in pairs], case.transitions, case.frame_rate, lopo.TOL_S,
        threshold=det.threshold, contrast=[(take(p), v) for p, v, _ in det.trace],
        gate_drops=[take(b) for b, _, sent in (det.gate.decisions if det.gate else ()) if not sent],
        refusals=[take(f) for f, _, _ in det.relative.refusals],
        span_like=span_resemblance(case.X, case.index, case.frame_rate))
    return errs, tally(pairs, case.transitions, case.frame_rate, lopo.TOL_S)


def summarise(cases: list[lopo.Case], found: dict[str, tuple[Errors, tuple]]) -> dict:
    by_source: dict[str, list[str]] = {}
    for c in cases:
        by_source.setdefault(c.source, []).append(c.name)

    def group(names: list[str]) -> dict:
        t = pooled_tally([found[n][1] for n in names])
        return {"performances": len(names), "transitions": t["transitions"],
                "cuts": t["cuts"], "f1": round(t["f1"], 4),
                **tally_errors(found[n][0] for n in names)}
    return {"pooled": group([c.name for c in cases]),
            "sources": {s: group(n) for s, n in sorted(by_source.items())}}


def _text(doc: dict) -> str:
    lines = []
    for name, g in [("pooled", doc["pooled"]), *doc["sources"].items()]:
        causes = ", ".join(f"{k} {v}" for k, v in g["miss_causes"].items())
        kinds = ", ".join(f"{k} {v}" for k, v in g["false_kinds"].items())
        lines.append(f"{name}: {g['transitions']} transitions, {g['cuts']} cuts, F1 {g['f1']:.4f}")
        lines.append(f"  missed {g['misses']}: {causes}")
        span = g["outside_span"]
        if any(span.values()):
            lines.append(f"  cut outside, the span to the range moves like: its labelled "
                         f"behaviour {span['labelled']}, the other side {span['other']}")
        lines.append(f"  false cuts {g['false_cuts']}: {kinds}")
        pairs = list(g["missed_pairs"].items())[:6]
        if pairs:
            lines.append("  missed most: " + ", ".join(f"{k} {v}" for k, v in pairs))
        inside = list(g["false_inside"].items())[:6]
        if inside:
            lines.append("  false cuts inside: " + ", ".join(f"{k} {v}" for k, v in inside))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    lopo.add_performance_arguments(p)
    p.add_argument("--params", metavar="FILE",
                   help="detector parameters (a file, or a shipped name such as fast)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    params = lopo.checked_params(args, "errors")
    if params is None:
        return 2
    cases = lopo.load_cases(args.data, args.cache, args.per_person, args.seeds)
    if not cases:
        print(f"errors: {args.data}: no labelled performance", file=sys.stderr)
        return 2
    found = {c.name: performance_errors(c, params) for c in cases}
    doc = {"data": str(args.data), "seeds": args.seeds, "params": args.params or "shipped",
           **summarise(cases, found)}
    if args.json:
        doc["performances"] = {n: e.as_dict() for n, (e, _) in found.items()}
        print(json.dumps(doc, indent=1, default=float))
    else:
        print(_text(doc))
    return 0


if __name__ == "__main__":
    sys.exit(main())
