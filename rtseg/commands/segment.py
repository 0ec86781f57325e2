"""``rtseg segment PATH...``: cut recorded takes into behaviours.

One take and no ``--out``: print its cuts and the segments between them (table, JSON or
CSV; frames are 0-based; a cut frame is the first frame of a segment).  Many takes
(files, folders searched recursively, globs) or ``--out FILE``: one record per take and
method, as JSON lines or Parquet, resumable, optionally on Dask (``rtseg.archive.runner``).
"""

from __future__ import annotations

import argparse
import csv
import glob
import io
import json
import shlex
import sys
import warnings
from pathlib import Path
from typing import Any

from rtseg.cli import params_file
from rtseg.archive.runner import SESSION_HEADER
from rtseg.identity.segments import identify_take
from rtseg.detectors.segmentation import METHODS, SegmentationResult, load_params, segment_take_methods


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
                    "the segments between them.  Frames are 0-based at the take's rate.  "
                    "Given several takes (files, folders searched recursively, glob "
                    "patterns) or --out, write one record per take and method (JSON lines "
                    "on stdout, or to --out FILE: .jsonl, or .parquet with pyarrow); takes "
                    "already in FILE are skipped, so an interrupted run resumes.")
    p.add_argument("paths", nargs="+", metavar="PATH",
                   help="take file, session folder, folder of takes (recursive) or glob")
    p.add_argument("--skeleton", metavar="ASF", help="ASF skeleton of an .amc take "
                   "(default: SS.asf beside SS_TT.amc)")
    add_method_argument(p, "all")
    p.add_argument("--format", choices=["table", "json", "csv"], default=None,
                   help="output format of a single take without --out (default table)")
    p.add_argument("--params", type=params_file, metavar="FILE",
                   help="detector parameters, TOML or JSON: flat, or one table per method")
    add_profile_argument(p)
    p.add_argument("--identify", action="store_true",
                   help="give each segment a behaviour id (1.. in order of first "
                        "appearance in its take; same id = same behaviour): gmm its majority "
                        "mixture component, the other methods the live identity tracker fed "
                        "the take's features and that method's cuts (final ids, after "
                        "corrections); a 'behaviour' column / JSON field (one take) or a "
                        "'behaviour' field in each segment of the records (archives)")
    p.add_argument("--behaviours", metavar="LIB", default=None,
                   help="with --identify (one take): also name each segment with this "
                        "behaviour library (rtseg learn), as 'rtseg live --behaviours' would: "
                        "a 'name' column / JSON field, 'unknown' for a segment unlike every "
                        "example")
    p.add_argument("--identity-threshold", type=float, metavar="D", default=None,
                   help="tracker distance at or below which a segment is an earlier "
                        "behaviour (default 4.0, as rtseg live's; see docs/identity.md)")
    a = p.add_argument_group("archives (many takes)")
    a.add_argument("--out", metavar="FILE",
                   help="write records to FILE (.jsonl, or .parquet with pyarrow); takes "
                        "already there are skipped")
    a.add_argument("--force", action="store_true", help="redo takes already in --out")
    a.add_argument("--retry-errors", action="store_true",
                   help="redo takes whose records in --out hold an error")
    a.add_argument("--workers", type=int, metavar="N",
                   help="run on a local Dask cluster of N worker processes "
                        "(pip install 'rtseg[scale]'; without Dask: in this process)")
    a.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a running Dask scheduler (e.g. tcp://host:8786); its workers "
                        "must have rtseg installed and see the take paths")
    a.add_argument("--limit", type=int, metavar="N",
                   help="run at most N takes not yet done (the rest stay for the next run)")
    a.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    p.set_defaults(func=run)


def add_profile_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--profile", metavar="NAME",
                        help="skeleton profile choosing the feature joints "
                             "(config/skeletons.toml; default: chosen from the joint names)")


def _single_take(args: argparse.Namespace) -> bool:
    """One PATH naming one take (a file, or a session folder, or a missing path: its
    error) and nothing asking for records: today's table/JSON/CSV output."""
    if len(args.paths) != 1 or args.out or args.workers or args.scheduler \
            or args.force or args.retry_errors or args.limit is not None:
        return False
    p = Path(args.paths[0])
    if p.is_dir():
        return (p / SESSION_HEADER).is_file()
    return p.exists() or not glob.has_magic(args.paths[0])


def run(args: argparse.Namespace) -> int:
    methods = methods_of(args.method)
    params = params_by_method(args.params, methods)
    if getattr(args, "identity_threshold", None) is not None \
            and not getattr(args, "identify", False):
        raise ValueError("--identity-threshold goes with --identify")
    lib_path = getattr(args, "behaviours", None)
    if lib_path and not getattr(args, "identify", False):
        raise ValueError("--behaviours goes with --identify")
    if lib_path and not _single_take(args):
        raise ValueError("--behaviours names the segments of one take (not archives)")
    if _single_take(args):
        from rtseg.drivers.readers import read_take
        path = args.paths[0]
        take = read_take(path, skeleton=args.skeleton)
        for note in (missing_frames_note(path, take), recorded_params_note(path, take, params)):
            if note:
                print(f"rtseg segment: warning: {note}", file=sys.stderr)
        if getattr(args, "identify", False):
            results = identify_take(take, methods, params, profile=args.profile,
                                    threshold=args.identity_threshold)
        else:
            results = segment_take_methods(take, methods, params, profile=args.profile)
        names = None
        if lib_path:
            from rtseg.library.file import load as load_library
            from rtseg.evaluation.online import live_config
            from rtseg.identity.segments import name_take
            names = name_take(take, results, load_library(lib_path), live_config()[0],
                              threshold=args.identity_threshold)
        if args.format == "json":
            from rtseg.core.features import PoseFeatures
            used = PoseFeatures.for_take(take, args.profile).report()
            sys.stdout.write(format_json(path, results, names, features=used))
            return 0
        out = {"table": format_table, "csv": format_csv}[args.format or "table"]
        sys.stdout.write(out(path, results, names))
        return 0
    return run_many(args, methods, params)


def missing_frames_note(path: str, take: Any) -> str:
    """What to say when ``take`` is a recorded session that misses frames its source sent
    (``missing_frames`` of ``rtseg.recording.read_session``): its frames and times count
    the recorded frames only, so they run early after each gap; "" otherwise."""
    lost = take.meta.get("missing_frames") if isinstance(take.meta, dict) else None
    if not lost:
        return ""
    return (f"{path}: the source sent {lost} frames that are not in this recording "
            f"({take.meta.get('gaps', '?')} gaps); frames and times below count the "
            f"{take.n_frames} recorded frames, so after a gap they are early by the frames "
            "lost before it (the session's own cut times are in its cuts.jsonl)")


def recorded_params_note(path: str, take: Any, params: dict[str, dict[str, Any]]) -> str:
    """What to say when ``take`` is a recorded session whose detectors ran with other
    parameters (``meta["session_meta"]["detector_params"]``) than ``params`` give: the
    differing keys of each method both have (``rtseg.archive.records.param_differences``);
    "" otherwise."""
    from rtseg.archive.records import param_differences
    diffs = [f"{m} {d}" for m, ds in param_differences(take, params).items() for d in ds]
    if not diffs:
        return ""
    more = f" and {len(diffs) - 4} more" if len(diffs) > 4 else ""
    return (f"{path}: the live session ran its detectors with other parameters: "
            f"{'; '.join(diffs[:4])}{more}; give --params {shlex.quote(str(path))} to cut as it did")


def run_many(args: argparse.Namespace, methods: list[str],
             params: dict[str, dict[str, Any]]) -> int:
    """Records of every take (``rtseg.archive.runner.run_archive``); exit 1 when a take failed."""
    from rtseg.archive.runner import run_archive
    if args.format not in (None, "json"):
        raise ValueError(f"--format {args.format} is for one take; several takes give one "
                         "JSON record per take and method (on stdout, or --out FILE)")
    for flag in ("force", "retry_errors"):
        if getattr(args, flag) and not args.out:
            raise ValueError(f"--{flag.replace('_', '-')} needs --out FILE")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be at least 1, got {args.workers}")
    if args.workers and args.scheduler:
        raise ValueError("give --workers (a local cluster) or --scheduler (a running one), "
                         "not both")
    lossy: dict[str, int] = {}          # recordings missing frames: take -> frames
    differ: list[str] = []              # recordings whose session ran other parameters

    def note_lost(path: str, records: list[dict[str, Any]]) -> None:
        lost = next((r.get("missing_frames") for r in records if r.get("missing_frames")), 0)
        if lost:
            lossy[records[0].get("take") or path] = lost
        if any(r.get("params_differ") for r in records):
            differ.append(records[0].get("take") or path)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        stats = run_archive(args.paths, methods, args.out, params, profile=args.profile,
                            on_take=note_lost,
                            skeleton=args.skeleton, workers=args.workers,
                            scheduler=args.scheduler, force=args.force,
                            retry_errors=args.retry_errors, limit=args.limit,
                            progress=not args.no_progress,
                            identify=getattr(args, "identify", False),
                            identity_threshold=getattr(args, "identity_threshold", None))
    for w in caught:
        print(f"rtseg segment: warning: {w.message}", file=sys.stderr)
    if lossy:
        named = ", ".join(f"{t} ({n})" for t, n in sorted(lossy.items()))
        print(f"rtseg segment: warning: {len(lossy)} recorded session(s) miss frames their "
              f"source sent: {named}; their frames and times count the recorded frames, so "
              "after a gap they are early (records: missing_frames, gaps)", file=sys.stderr)
    if differ:
        print(f"rtseg segment: warning: {len(differ)} recorded session(s) ran their detectors "
              f"with other parameters: {', '.join(sorted(differ))}; give --params SESSION "
              "(the recording's folder: the parameters it ran with) to cut as it did "
              "(records: params_differ)", file=sys.stderr)
    if stats.failed:
        where = f" (errors in {args.out})" if args.out else ""
        print(f"rtseg segment: {stats.failed} of {stats.run} takes failed{where}",
              file=sys.stderr)
    if stats.skipped_failed:
        print(f"rtseg segment: {stats.skipped_failed} of the {stats.skipped} takes skipped "
              f"(done before) failed then (errors in {args.out}; --retry-errors redoes them)",
              file=sys.stderr)
    return 1 if stats.failed else 0


def format_table(name: str, results: dict[str, SegmentationResult],
                 names: dict[str, list[str]] | None = None) -> str:
    """Cuts and segments per method; ``names`` (``--behaviours``): a last ``name`` column."""
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
        ident = bool(r.segments) and r.segments[0].behaviour is not None
        nm = (names or {}).get(method)
        lines.append(f"  {'seg':>4} {'start':>7} {'end':>7} {'start_s':>9} {'end_s':>9} "
                     f"{'duration_s':>10}" + (f" {'behaviour':>9}" if ident else "")
                     + ("  name" if nm is not None else ""))
        for k, s in enumerate(r.segments):
            lines.append(f"  {s.index:>4} {s.start:>7} {s.end:>7} {s.start_time:>9.3f} "
                         f"{s.end_time:>9.3f} {s.duration:>10.3f}"
                         + (f" {s.behaviour:>9}" if ident else "")
                         + (f"  {nm[k]}" if nm is not None else ""))
    return "\n".join(lines) + "\n"


def format_json(name: str, results: dict[str, SegmentationResult],
                names: dict[str, list[str]] | None = None,
                features: dict | None = None) -> str:
    """One document; ``names`` (``--behaviours``): a ``name`` field in each segment;
    ``features``: the joints used (``PoseFeatures.report``)."""
    first = next(iter(results.values()))
    doc = {"take": name, "n_frames": first.n_frames, "frame_rate": first.frame_rate,
           "methods": {}}
    if features is not None:
        doc["features"] = features
    for m, r in results.items():
        d = r.as_dict()
        nm = (names or {}).get(m)
        if nm is not None:
            d["segments"] = [{**seg, "name": n} for seg, n in zip(d["segments"], nm)]
        doc["methods"][m] = {"cuts": d["cuts"], "segments": d["segments"],
                             "elapsed_s": round(r.elapsed_s, 4)}
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def format_csv(name: str, results: dict[str, SegmentationResult],
               names: dict[str, list[str]] | None = None) -> str:
    """One row per segment; ``cut_confidence`` is that of the cut opening the segment
    (empty for segment 0, which starts the take); with identities (``--identify``) a
    ``behaviour`` column, with ``names`` (``--behaviours``) a last ``name`` column."""
    ident = any(s.behaviour is not None for r in results.values() for s in r.segments)
    named = names is not None
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["method", "segment", "start_frame", "end_frame", "start_s", "end_s",
                "duration_s", "cut_confidence"] + (["behaviour"] if ident else [])
               + (["name"] if named else []))
    for m, r in results.items():
        conf = {c.frame: c.confidence for c in r.cuts}
        nm = (names or {}).get(m) or [""] * len(r.segments)
        for k, s in enumerate(r.segments):
            c = conf.get(s.start)
            w.writerow([m, s.index, s.start, s.end, f"{s.start_time:.6f}", f"{s.end_time:.6f}",
                        f"{s.duration:.6f}", "" if c is None else f"{c:.4f}"]
                       + ([s.behaviour] if ident else []) + ([nm[k]] if named else []))
    return buf.getvalue()
