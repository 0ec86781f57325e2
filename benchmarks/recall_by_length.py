#!/usr/bin/env python3
"""Which transitions the live detector misses: recall by the length of the segments around
each transition.

    python3 benchmarks/recall_by_length.py ../shared/data [/tmp/spliced_same ...] [--json]

Every labelled take of each folder (groups cmu, tsseg4d and spliced; ``benchmarks/splice.py``
output is a folder of group spliced) goes through the live pipeline with the shipped
defaults (``rtseg.evaluation.online``: the features and detector ``rtseg live`` runs), and its
cuts are matched to the labelled ranges widened by 0.5 s (``rtseg.evaluation.scoring``, maximum
matching).  Each transition is then binned by the length of the segment **before** it
(labelled mid of the previous transition, or the take's start, to this one's mid, in
seconds) and, separately, of the segment **after** it; the recall of each bin is printed
per group.  Nothing is tuned here: it says where the detector's windows (3 s before, 1.75
s after, see docs/live_detector.md) run out of room.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from rtseg.evaluation.scoring import score, widen
from rtseg.labels.takes import find_labelled_takes
from rtseg.evaluation.online import live_config, live_cuts

TOL_S = 0.5
BINS_S = (0.0, 3.5, 5.0, 7.0, float("inf"))


def transitions_of(folder: Path) -> list[tuple[str, bool, float, float]]:
    """(group, matched, seconds of the segment before, seconds of the segment after) of
    every labelled transition of ``folder``."""
    cfg, default = live_config()
    rows = []
    for lt in find_labelled_takes(folder, ("cmu", "tsseg4d", "spliced")):
        take = lt.load()
        fr = take.frame_rate
        cuts = live_cuts(take, cfg)[default]
        tr = list(lt.transitions)
        sc = score([c.boundary for c in cuts], widen(tr, int(round(TOL_S * fr))))
        hit = {t for _, t in sc.matches}
        ends = [0] + [t.mid for t in tr] + [take.n_frames]
        for i, t in enumerate(tr):
            rows.append((lt.group, i in hit, (t.mid - ends[i]) / fr, (ends[i + 2] - t.mid) / fr))
    return rows


def binned(rows: list[tuple[str, bool, float, float]], col: int) -> list[dict]:
    out = []
    for lo, hi in zip(BINS_S[:-1], BINS_S[1:]):
        sel = [r[1] for r in rows if lo <= r[col] < hi]
        out.append({"from_s": lo, "to_s": hi, "transitions": len(sel),
                    "recall": round(float(np.mean(sel)), 3) if sel else None})
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    rows = []
    for f in args.folders:
        if not f.is_dir():
            print(f"recall_by_length: {f} is not a folder", file=sys.stderr)
            return 2
        rows += transitions_of(f)
    report = {}
    for g in sorted({r[0] for r in rows}):
        rg = [r for r in rows if r[0] == g]
        report[g] = {"transitions": len(rg), "recall": round(float(np.mean([r[1] for r in rg])), 3),
                     "by_segment_before": binned(rg, 2), "by_segment_after": binned(rg, 3)}
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    for g, r in report.items():
        print(f"{g}: {r['transitions']} transitions, recall {r['recall']:.3f} (live default, +-{TOL_S} s)")
        for key, label in (("by_segment_before", "before"), ("by_segment_after", "after")):
            cells = [f"{b['from_s']:g}-{b['to_s']:g} s: {b['recall'] if b['recall'] is not None else '-'}"
                     f" ({b['transitions']})" for b in r[key]]
            print(f"  segment {label:<6} " + " | ".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
