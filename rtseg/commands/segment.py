"""``rtseg segment TAKE``: cut a recorded take into behaviours and print the cuts and the
segments between them (frames are 0-based; a cut frame is the first frame of a segment)."""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from typing import Any

from rtseg.segmentation import METHODS, SegmentationResult, load_params, segment_take_methods


def add_method_argument(parser: argparse.ArgumentParser, default: str) -> None:
    parser.add_argument("--method", default=default, choices=[*METHODS, "all"],
                        help=f"detector: {', '.join(METHODS)} or all (default {default})")


def methods_of(choice: str) -> list[str]:
    return list(METHODS) if choice == "all" else [choice]


def params_by_method(path: str | None, methods: list[str]) -> dict[str, dict[str, Any]]:
    """{method: parameters} from a --params file (flat, or one table per method)."""
    return {m: load_params(path, m) for m in methods}


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "segment", help="cut a recorded take into behaviours",
        description="Segment a recorded take (.amc with its .asf, .bvh, .npz, tsseg4d .csv, "
                    "or a recorded session folder) and print the cut frames and times and "
                    "the segments between them.  Frames are 0-based at the take's rate.")
    p.add_argument("take", help="take file or session folder")
    p.add_argument("--skeleton", metavar="ASF", help="ASF skeleton of an .amc take "
                   "(default: SS.asf beside SS_TT.amc)")
    add_method_argument(p, "all")
    p.add_argument("--format", choices=["table", "json", "csv"], default="table",
                   help="output format (default table)")
    p.add_argument("--params", metavar="FILE",
                   help="detector parameters, TOML or JSON: flat, or one table per method")
    add_profile_argument(p)
    p.set_defaults(func=run)


def add_profile_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--profile", metavar="NAME",
                        help="skeleton profile choosing the feature joints "
                             "(config/skeletons.toml; default: chosen from the joint names)")


def run(args: argparse.Namespace) -> int:
    from rtseg.take import load_take
    methods = methods_of(args.method)
    params = params_by_method(args.params, methods)
    take = load_take(args.take, skeleton=args.skeleton)
    results = segment_take_methods(take, methods, params, profile=args.profile)
    out = {"table": format_table, "json": format_json, "csv": format_csv}[args.format]
    sys.stdout.write(out(args.take, results))
    return 0


def format_table(name: str, results: dict[str, SegmentationResult]) -> str:
    lines = []
    first = next(iter(results.values()))
    lines.append(f"{name}: {first.n_frames} frames at {first.frame_rate:g} fps "
                 f"({first.n_frames / first.frame_rate:.2f} s)")
    for method, r in results.items():
        lines.append("")
        lines.append(f"{method}: {len(r.cuts)} cut{'s' if len(r.cuts) != 1 else ''}, "
                     f"{len(r.segments)} segments ({r.elapsed_s:.2f} s to compute)")
        if r.cuts:
            lines.append(f"  {'cut':>4} {'frame':>7} {'time_s':>9} {'confidence':>10}")
            for k, c in enumerate(r.cuts, start=1):
                lines.append(f"  {k:>4} {c.frame:>7} {c.frame / r.frame_rate:>9.3f} "
                             f"{c.confidence:>10.2f}")
        lines.append(f"  {'seg':>4} {'start':>7} {'end':>7} {'start_s':>9} {'end_s':>9} "
                     f"{'duration_s':>10}")
        for s in r.segments:
            lines.append(f"  {s.index:>4} {s.start:>7} {s.end:>7} {s.start_time:>9.3f} "
                         f"{s.end_time:>9.3f} {s.duration:>10.3f}")
    return "\n".join(lines) + "\n"


def format_json(name: str, results: dict[str, SegmentationResult]) -> str:
    first = next(iter(results.values()))
    doc = {"take": name, "n_frames": first.n_frames, "frame_rate": first.frame_rate,
           "methods": {}}
    for m, r in results.items():
        d = r.as_dict()
        doc["methods"][m] = {"cuts": d["cuts"], "segments": d["segments"],
                             "elapsed_s": round(r.elapsed_s, 4)}
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def format_csv(name: str, results: dict[str, SegmentationResult]) -> str:
    """One row per segment; ``cut_confidence`` is that of the cut opening the segment
    (empty for segment 0, which starts the take)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["method", "segment", "start_frame", "end_frame", "start_s", "end_s",
                "duration_s", "cut_confidence"])
    for m, r in results.items():
        conf = {c.frame: c.confidence for c in r.cuts}
        for s in r.segments:
            c = conf.get(s.start)
            w.writerow([m, s.index, s.start, s.end, f"{s.start_time:.6f}", f"{s.end_time:.6f}",
                        f"{s.duration:.6f}", "" if c is None else f"{c:.4f}"])
    return buf.getvalue()
