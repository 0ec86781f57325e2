"""``rtseg evaluate DATA_DIR``: segment every labelled take of a data folder and score the
cuts against the labels (precision, recall, F1 per take and pooled over takes).

The folder is laid out like ``../shared/data`` (see ``rtseg.labels.takes.find_labelled_takes``).
Group "cmu" holds the full-rotation takes (what accuracy targets are about, the default);
"tsseg4d" the four-channel takes, reported separately.

Scoring: a cut is correct for a transition when it lies in the labelled range widened by
``--tolerance`` seconds on each side (default 0.5 s, the tolerance at which a second human
annotation agrees with the first: F1 0.98); the strict score (tolerance 0) is reported
beside it.  ``--online`` runs, instead of the offline methods, exactly what ``rtseg live``
runs (``rtseg.evaluation.online``: the live pipeline and detectors from the live configuration,
frame by frame) and reports each matched cut's detection delay: (frame whose arrival
produced the cut - labelled transition mid) / frame rate, in seconds.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from rtseg.cli import params_file
from rtseg.commands.segment import (
    add_method_argument, add_profile_argument, methods_of, params_by_method,
)
from rtseg.evaluation.scoring import Score, detection_delays, pooled, score, widen
from rtseg.labels.takes import GROUPS, LabelledTake, find_labelled_takes, no_takes_hint
from rtseg.detectors import ONLINE_METHODS
from rtseg.evaluation.online import live_config, live_cuts
from rtseg.progress import Progress
from rtseg.detectors.segmentation import segment_take_methods

log = logging.getLogger(__name__)


@dataclass
class TakeScore:
    """One method on one take: ``score`` at the tolerance, ``strict`` inside the labelled
    ranges; ``delays_s`` per matched transition (online runs only, else empty)."""
    name: str
    group: str
    score: Score
    cut_frames: list[int]
    label_source: str
    elapsed_s: float
    mids: list[int] = field(default_factory=list)
    strict: Score | None = None
    delays_s: list[float] = field(default_factory=list)
    detected_frames: list[int] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """Score counts and ratios (and ``strict``), the cut frames, and per matched
        transition its labelled ``mid`` and the matching cut (``offset`` = cut - mid,
        frames; online: ``delay_s``)."""
        delays = dict(zip((c for c, _ in self.score.matches), self.delays_s))
        matched = [{"mid": self.mids[j], "cut": c, "offset": c - self.mids[j],
                    **({"delay_s": round(delays[c], 4)} if c in delays else {})}
                   for c, j in self.score.matches] if self.mids else []
        out = {**self.score.as_dict(), "group": self.group, "cut_frames": self.cut_frames,
               "matched": sorted(matched, key=lambda m: m["mid"]),
               "labels": self.label_source, "elapsed_s": round(self.elapsed_s, 4)}
        if self.strict is not None:
            out["strict"] = _ratios(self.strict)
        if self.detected_frames:
            out["detected_frames"] = self.detected_frames
        return out


@dataclass
class MethodReport:
    """All takes of one method: per take, pooled per group, pooled over everything."""
    method: str
    takes: dict[str, TakeScore] = field(default_factory=dict)
    tolerance_s: float = 0.5
    online: bool = False

    def _takes(self, group: str | None) -> list[TakeScore]:
        return [t for t in self.takes.values() if group in (None, t.group)]

    def pooled(self, group: str | None = None) -> Score:
        return pooled(t.score for t in self._takes(group))

    def pooled_strict(self, group: str | None = None) -> Score:
        return pooled(t.strict for t in self._takes(group) if t.strict is not None)

    def delays(self, group: str | None = None) -> list[float]:
        return [d for t in self._takes(group) for d in t.delays_s]

    def groups(self) -> list[str]:
        return sorted({t.group for t in self.takes.values()},
                      key=lambda g: (GROUPS.index(g) if g in GROUPS else len(GROUPS), g))

    def summary(self, group: str | None = None) -> dict[str, Any]:
        """Pooled counts and ratios at the tolerance, ``strict`` ones, and (online)
        ``delay_s: {median, p90}`` of the matched cuts."""
        out = {**_pooled_dict(self.pooled(group)), "strict": _ratios(self.pooled_strict(group))}
        if self.online:
            d = self.delays(group)
            out["delay_s"] = ({"median": float(np.median(d)), "p90": float(np.percentile(d, 90))}
                              if d else {"median": None, "p90": None})
        return out

    def as_dict(self) -> dict[str, Any]:
        return {
            "tolerance_s": self.tolerance_s,
            "online": self.online,
            "pooled": self.summary(),
            "groups": {g: self.summary(g) for g in self.groups()},
            "takes": {k: t.as_dict() for k, t in self.takes.items()},
        }


def _ratios(s: Score) -> dict[str, float]:
    return {"precision": s.precision, "recall": s.recall, "f1": s.f1}


def _pooled_dict(s: Score) -> dict[str, Any]:
    return {"precision": s.precision, "recall": s.recall, "f1": s.f1,
            "cuts": s.cuts, "transitions": s.transitions, "tp": s.tp}


@dataclass
class EvaluationReport:
    methods: dict[str, MethodReport]
    errors: dict[str, str] = field(default_factory=dict)
    live_default: str | None = None
    #: the ``--params`` file the detectors ran with (as given), None for the shipped ones
    params_file: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """``{method: {"tolerance_s", "online", "pooled", "groups", "takes"[, "errors",
        "params_file"]}}``; takes that failed are listed under every method; ``params_file``
        the ``--params`` given; online runs add a top-level ``"live_default"``: the name
        of the default live detector."""
        doc: dict[str, Any] = {}
        if self.live_default is not None:
            doc["live_default"] = self.live_default
        doc.update({m: r.as_dict() for m, r in self.methods.items()})
        for m in self.methods:
            if self.errors:
                doc[m]["errors"] = dict(self.errors)
            if self.params_file is not None:
                doc[m]["params_file"] = self.params_file
        return doc


def select_groups(group: str) -> tuple[str, ...]:
    return GROUPS if group == "all" else (group,)


def _cuts_of_take(take: Any, methods: Sequence[str], params: dict[str, dict[str, Any]] | None,
                  profile: str | None, online: Any) -> dict[str, tuple[list[int], list[int], float]]:
    """{method: (cut frames, frames that produced them (online; else []), elapsed s)}."""
    if online is None:
        results = segment_take_methods(take, methods, params, profile=profile)
        return {m: (r.cut_frames, [], r.elapsed_s) for m, r in results.items()}
    t0 = time.perf_counter()
    cuts = live_cuts(take, online)
    elapsed = time.perf_counter() - t0
    return {m: ([c.boundary for c in cuts[m]], [c.detected for c in cuts[m]], elapsed)
            for m in methods}


def _load_and_cut(t: LabelledTake, methods: Sequence[str], params: dict[str, dict[str, Any]] | None,
                  profile: str | None, online: Any) -> tuple[int, float, dict[str, Any]]:
    """One take's task on a Dask worker: (frames, frame rate, ``_cuts_of_take``)."""
    take = t.load()
    return take.n_frames, take.frame_rate, _cuts_of_take(take, methods, params, profile, online)


def evaluate_takes(takes: Sequence[LabelledTake], methods: Sequence[str],
                   params: dict[str, dict[str, Any]] | None = None,
                   progress: Progress | None = None, profile: str | None = None,
                   tolerance_s: float = 0.5, online: Any = None,
                   workers: int | None = None, scheduler: str | None = None) -> EvaluationReport:
    """Segment each take with every method (features computed once a take) and score it,
    at ``tolerance_s`` and strictly.

    ``online``: a live configuration (``rtseg.evaluation.online.live_config``) whose detectors
    are ``methods``: the take's frames go through the live pipeline instead of the offline
    methods, and the delay of every matched cut is kept.
    Take keys are the bare take names, or ``group/name`` when a name occurs in two groups.
    A take that cannot be read or segmented is logged and listed in ``errors``.
    ``workers``/``scheduler``: read and segment the takes on Dask, one task per take
    (``rtseg.archive.executors.map_tasks``); scoring and the report are unchanged.
    """
    if not (tolerance_s >= 0 and math.isfinite(tolerance_s)):
        raise ValueError(f"tolerance must be a finite number of seconds >= 0, got {tolerance_s}")
    names = [t.name for t in takes]
    clash = {n for n in names if names.count(n) > 1}
    report = EvaluationReport({m: MethodReport(m, tolerance_s=tolerance_s,
                                               online=online is not None) for m in methods})
    parallel = bool(workers or scheduler)
    ahead: dict[int, tuple[Any, BaseException | None]] = {}
    if parallel:
        from rtseg.archive.executors import map_tasks
        for i, res, exc in map_tasks(_load_and_cut, takes, {"methods": list(methods),
                                     "params": params, "profile": profile, "online": online},
                                     workers, scheduler):
            ahead[i] = (res, exc)
            if progress:
                progress.step(takes[i].name)
    for i, t in enumerate(takes):
        key = f"{t.group}/{t.name}" if t.name in clash else t.name
        if progress and not parallel:
            progress.step(key)
        try:
            if parallel:
                res, exc = ahead.pop(i)
                if exc is not None:
                    raise exc
                n_frames, rate, results = res
            else:
                take = t.load()
                n_frames, rate = take.n_frames, take.frame_rate
            if t.labels.n_frames is not None and abs(t.labels.n_frames - n_frames) > 12:
                log.warning("%s: labels say %d frames, the take has %d", key,
                            t.labels.n_frames, n_frames)
            if not parallel:
                results = _cuts_of_take(take, methods, params, profile, online)
        except (OSError, ValueError, KeyError) as exc:
            log.error("%s: %s", key, exc)
            report.errors[key] = str(exc)
            continue
        wide = widen(t.transitions, int(round(tolerance_s * rate)))
        for m, (frames_, detected, elapsed) in results.items():
            sc = score(frames_, wide)
            delays = (detection_delays(sc, dict(zip(frames_, detected)), wide, rate)
                      if detected else [])
            report.methods[m].takes[key] = TakeScore(
                t.name, t.group, sc, frames_, t.label_source, elapsed,
                [tr.mid for tr in t.transitions], strict=score(frames_, t.transitions),
                delays_s=delays, detected_frames=detected)
    if progress:
        progress.close()
    return report


def evaluate_dir(data_dir: str | Path, methods: Sequence[str], group: str | None = None,
                 params: dict[str, dict[str, Any]] | None = None,
                 progress: bool = True, profile: str | None = None,
                 tolerance_s: float = 0.5, online: Any = None,
                 workers: int | None = None, scheduler: str | None = None) -> EvaluationReport:
    """Find the labelled takes of ``data_dir`` in ``group`` (one of ``GROUPS`` or "all";
    None: the cmu takes when there are any, else every group found, e.g. a folder of
    spliced performances) and evaluate them (see ``evaluate_takes``)."""
    if group is None:
        takes = find_labelled_takes(data_dir, GROUPS)
        cmu = [t for t in takes if t.group == "cmu"]
        takes = cmu or takes
        group = "cmu" if cmu else "any"
    else:
        takes = find_labelled_takes(data_dir, select_groups(group))
    if not takes:
        which = "no labelled takes" if group == "any" else f"no labelled takes of group {group!r}"
        raise ValueError(f"{which} found in {data_dir}" + no_takes_hint(data_dir))
    bar = Progress(len(takes), enabled=progress)
    return evaluate_takes(takes, methods, params, bar, profile, tolerance_s, online,
                          workers, scheduler)


def _delay_cells(r: MethodReport, delays: list[float]) -> str:
    """The median and p90 delay columns (online reports only)."""
    if not r.online:
        return ""
    return (f"  {np.median(delays):>5.2f} {np.percentile(delays, 90):>5.2f}" if delays else
            f"  {'-':>5} {'-':>5}")


def format_table(report: EvaluationReport) -> str:
    lines = []
    for m, r in report.methods.items():
        tol = f"+-{r.tolerance_s:g}s"
        hdr = (f"{'method':<8} {'take':<16} {'cuts':>5} {'trans':>5} {'tp':>4} {'prec':>6} "
               f"{'recall':>6} {'f1':>6} {'strict':>6}"
               + (f"  {'delay':>5} {'p90':>5}" if r.online else "") + "  labels")
        lines.append(f"{m}{' (live)' if r.online else ''}{' [default live detector]' if m == report.live_default else ''}: "
                     f"F1 with cuts within {tol} of the labelled ranges; strict = inside them"
                     + ("; delay = median/p90 s from the labelled transition to the frame "
                        "that produced the cut" if r.online else "")
                     + (f"; parameters {report.params_file}" if report.params_file else ""))
        lines.append(hdr)
        for key, t in r.takes.items():
            s, st = t.score, t.strict
            lines.append(f"{m:<8} {key:<16} {s.cuts:>5} {s.transitions:>5} {s.tp:>4} "
                         f"{s.precision:>6.3f} {s.recall:>6.3f} {s.f1:>6.3f} "
                         f"{st.f1 if st else float('nan'):>6.3f}"
                         f"{_delay_cells(r, t.delays_s)}  {t.label_source}")
        groups = r.groups() + ([None] if len(r.groups()) > 1 else [])
        for g in groups:
            s, st = r.pooled(g), r.pooled_strict(g)
            lines.append(f"{m:<8} {'POOLED ' + (g or 'all'):<16} {s.cuts:>5} {s.transitions:>5} "
                         f"{s.tp:>4} {s.precision:>6.3f} {s.recall:>6.3f} {s.f1:>6.3f} "
                         f"{st.f1:>6.3f}{_delay_cells(r, r.delays(g))}")
        lines.append("")
    if report.errors:
        lines.append("takes that failed:")
        lines.extend(f"  {k}: {v}" for k, v in report.errors.items())
    return "\n".join(lines).rstrip("\n") + "\n"


def add_evaluate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("data_dir", help="folder laid out like ../shared/data "
                   "(cmu/, labels/, tsseg4d/), or a folder of spliced .npz performances")
    add_method_argument(p, "all")
    p.add_argument("--group", choices=[*GROUPS, "all"], default=None,
                   help="which takes: cmu (full-rotation takes; the default when the folder "
                        "has any, else every group found), tsseg4d (four-channel takes), "
                        "spliced (performances written by benchmarks/splice.py) or all "
                        "(pooled per group and overall)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--params", type=params_file, metavar="FILE",
                   help="detector parameters, TOML or JSON: flat, or one table per method "
                        "(with --online: one table per method, the live configuration's "
                        "detectors.params); "
                        "'full' and 'fast' are the shipped config/full.toml and "
                        "config/fast.toml")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.add_argument("--tolerance", type=tolerance_seconds, default=0.5, metavar="S",
                   help="a cut counts for a transition within S seconds outside its labelled "
                        "range (default 0.5: where a second human annotation agrees with "
                        "the first); the strict score (S = 0) is always given beside it")
    p.add_argument("--online", action="store_true",
                   help="score what `rtseg live` would have sent: each take through the live "
                        "pipeline and detectors (config/live.toml or --config), frame by "
                        "frame, with each matched cut's detection delay")
    p.add_argument("--config", metavar="FILE",
                   help="live configuration for --online (default: the shipped live.toml)")
    p.add_argument("--identity", action="store_true",
                   help="with --online: score the behaviour ids the live loop sends "
                        "(adjusted Rand index, NMI per take and pooled; rtseg.evaluation.identity) "
                        "instead of the cuts; takes: cmu and tsseg4d unless --group")
    p.add_argument("--behaviours", metavar="LIB",
                   help="with --online --identity: the live loop names the segments with "
                        "this behaviour library (rtseg learn); adds identity.named: right / "
                        "unknown / wrong shares over the segments of its behaviours")
    add_profile_argument(p)
    p.add_argument("--workers", type=worker_count, metavar="N",
                   help="read and segment the takes on a local Dask cluster of N processes, "
                        "N >= 1 (pip install 'rtseg[scale]'; same report; without it: in "
                        "this process)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="read and segment the takes on a running Dask scheduler "
                        "(tcp://host:8786; its workers see the data folder)")


def worker_count(text: str) -> int:
    """argparse type: a whole number of worker processes >= 1."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(
            f"must be at least 1, got {v} (leave --workers out to run in this process)")
    return v


def tolerance_seconds(text: str) -> float:
    """argparse type: a finite number of seconds >= 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (v >= 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds >= 0, got {text}")
    return v


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "evaluate", help="score the detectors against labelled takes",
        description="Segment every labelled take of DATA_DIR and print precision, recall "
                    "and F1 per take and pooled (counts summed over takes, then divided).")
    add_evaluate_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if getattr(args, "behaviours", None) and not getattr(args, "identity", False):
        raise ValueError("--behaviours names the identity's segments: add --online --identity")
    if getattr(args, "identity", False) and (args.workers or args.scheduler):
        raise ValueError("--identity runs in this process: drop --workers/--scheduler")
    if args.online and args.profile:
        raise ValueError("--online takes the features of the live configuration: give "
                         "--config FILE instead of --profile")
    if getattr(args, "identity", False):          # separate path: rtseg.evaluation.identity
        from rtseg.evaluation.report import run_evaluate_identity
        return run_evaluate_identity(args)
    online = live_default = None
    if args.online:
        methods = list(ONLINE_METHODS) if args.method == "all" else [args.method]
        if any(m not in ONLINE_METHODS for m in methods):
            raise ValueError(f"--online: {args.method} has no live detector "
                             f"(live: {', '.join(ONLINE_METHODS)})")
        online, live_default = live_config(args.config, methods, args.params)
    else:
        if args.config:
            raise ValueError("--config goes with --online (offline methods take --params)")
        methods = methods_of(args.method)
    report = evaluate_dir(args.data_dir, methods, args.group,
                          None if online else params_by_method(args.params, methods),
                          progress=not args.no_progress, profile=args.profile,
                          tolerance_s=args.tolerance, online=online,
                          workers=args.workers, scheduler=args.scheduler)
    report.live_default = live_default
    report.params_file = args.params
    if args.json:
        sys.stdout.write(json.dumps(report.as_dict(), indent=2, allow_nan=False) + "\n")
    else:
        sys.stdout.write(format_table(report))
    for key, msg in report.errors.items():
        print(f"rtseg evaluate: {key} not scored: {msg}", file=sys.stderr)
    return 1 if report.errors else 0
