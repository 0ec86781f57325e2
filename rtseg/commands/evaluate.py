"""``rtseg evaluate DATA_DIR``: segment every labelled take of a data folder and score the
cuts against the labels (precision, recall, F1 per take and pooled over takes).

The folder is laid out like ``../shared/data`` (see ``rtseg.labels.find_labelled_takes``).
Group "cmu" holds the full-rotation takes (what accuracy targets are about, the default);
"tsseg4d" the four-channel takes, reported separately.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence, TextIO

from rtseg.commands.segment import (
    add_method_argument, add_profile_argument, methods_of, params_by_method,
)
from rtseg.evaluation import Score, pooled, score
from rtseg.labels import GROUPS, LabelledTake, find_labelled_takes
from rtseg.segmentation import segment_take_methods

log = logging.getLogger(__name__)


class Progress:
    """A one-line progress bar on a terminal (stderr); one plain line per step otherwise."""

    def __init__(self, total: int, stream: TextIO | None = None, enabled: bool = True,
                 width: int = 24) -> None:
        self.total = max(total, 1)
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.width = width
        self.done = 0
        self.t0 = time.monotonic()
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def step(self, label: str) -> None:
        """Announce the step about to run (``label``), counting the previous one as done."""
        if not self.enabled:
            return
        n = self.done
        fill = int(self.width * n / self.total)
        bar = "#" * fill + "-" * (self.width - fill)
        text = f"evaluate [{bar}] {n}/{self.total} {time.monotonic() - self.t0:5.1f}s {label}"
        if self.tty:
            self.stream.write("\r" + text[:100].ljust(100))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()
        self.done += 1

    def close(self) -> None:
        if not self.enabled:
            return
        text = (f"evaluate [{'#' * self.width}] {self.total}/{self.total} "
                f"{time.monotonic() - self.t0:5.1f}s done")
        self.stream.write(("\r" + text.ljust(100) + "\n") if self.tty else text + "\n")
        self.stream.flush()


@dataclass
class TakeScore:
    """One method on one take."""
    name: str
    group: str
    score: Score
    cut_frames: list[int]
    label_source: str
    elapsed_s: float
    mids: list[int] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """Score counts and ratios, the cut frames, and per matched transition its labelled
        ``mid`` and the matching cut (``offset`` = cut - mid, frames)."""
        matched = [{"mid": self.mids[j], "cut": c, "offset": c - self.mids[j]}
                   for c, j in self.score.matches] if self.mids else []
        return {**self.score.as_dict(), "group": self.group, "cut_frames": self.cut_frames,
                "matched": sorted(matched, key=lambda m: m["mid"]),
                "labels": self.label_source, "elapsed_s": round(self.elapsed_s, 4)}


@dataclass
class MethodReport:
    """All takes of one method: per take, pooled per group, pooled over everything."""
    method: str
    takes: dict[str, TakeScore] = field(default_factory=dict)

    def pooled(self, group: str | None = None) -> Score:
        return pooled(t.score for t in self.takes.values() if group in (None, t.group))

    def groups(self) -> list[str]:
        return sorted({t.group for t in self.takes.values()}, key=GROUPS.index)

    def as_dict(self) -> dict[str, Any]:
        p = self.pooled()
        return {
            "pooled": _pooled_dict(p),
            "groups": {g: _pooled_dict(self.pooled(g)) for g in self.groups()},
            "takes": {k: t.as_dict() for k, t in self.takes.items()},
        }


def _pooled_dict(s: Score) -> dict[str, Any]:
    return {"precision": s.precision, "recall": s.recall, "f1": s.f1,
            "cuts": s.cuts, "transitions": s.transitions, "tp": s.tp}


@dataclass
class EvaluationReport:
    methods: dict[str, MethodReport]
    errors: dict[str, str] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """``{method: {"pooled", "groups", "takes"[, "errors"]}}``; takes that failed are
        listed under every method (no top-level key besides the methods)."""
        doc: dict[str, Any] = {m: r.as_dict() for m, r in self.methods.items()}
        if self.errors:
            for d in doc.values():
                d["errors"] = dict(self.errors)
        return doc


def select_groups(group: str) -> tuple[str, ...]:
    return GROUPS if group == "all" else (group,)


def evaluate_takes(takes: Sequence[LabelledTake], methods: Sequence[str],
                   params: dict[str, dict[str, Any]] | None = None,
                   progress: Progress | None = None, profile: str | None = None
                   ) -> EvaluationReport:
    """Segment each take with every method (features computed once a take) and score it.

    Take keys are the bare take names, or ``group/name`` when a name occurs in two groups.
    A take that cannot be read or segmented is logged and listed in ``errors``.
    """
    names = [t.name for t in takes]
    clash = {n for n in names if names.count(n) > 1}
    report = EvaluationReport({m: MethodReport(m) for m in methods})
    for t in takes:
        key = f"{t.group}/{t.name}" if t.name in clash else t.name
        if progress:
            progress.step(key)
        try:
            take = t.load()
            if t.labels.n_frames is not None and abs(t.labels.n_frames - take.n_frames) > 12:
                log.warning("%s: labels say %d frames, the take has %d", key,
                            t.labels.n_frames, take.n_frames)
            results = segment_take_methods(take, methods, params, profile=profile)
        except (OSError, ValueError, KeyError) as exc:
            log.error("%s: %s", key, exc)
            report.errors[key] = str(exc)
            continue
        for m, r in results.items():
            report.methods[m].takes[key] = TakeScore(
                t.name, t.group, score(r.cut_frames, t.transitions), r.cut_frames,
                t.label_source, r.elapsed_s, [tr.mid for tr in t.transitions])
    if progress:
        progress.close()
    return report


def evaluate_dir(data_dir: str | Path, methods: Sequence[str], group: str = "cmu",
                 params: dict[str, dict[str, Any]] | None = None,
                 progress: bool = True, profile: str | None = None) -> EvaluationReport:
    """Find the labelled takes of ``data_dir`` in ``group`` ("cmu", "tsseg4d" or "all")
    and evaluate them."""
    takes = find_labelled_takes(data_dir, select_groups(group))
    if not takes:
        raise ValueError(f"no labelled takes of group {group!r} found in {data_dir}")
    bar = Progress(len(takes), enabled=progress)
    return evaluate_takes(takes, methods, params, bar, profile)


def format_table(report: EvaluationReport) -> str:
    lines = []
    hdr = (f"{'method':<6} {'take':<16} {'cuts':>5} {'trans':>5} {'tp':>4} {'prec':>6} "
           f"{'recall':>6} {'f1':>6}  labels")
    for m, r in report.methods.items():
        lines.append(hdr)
        for key, t in r.takes.items():
            s = t.score
            lines.append(f"{m:<6} {key:<16} {s.cuts:>5} {s.transitions:>5} {s.tp:>4} "
                         f"{s.precision:>6.3f} {s.recall:>6.3f} {s.f1:>6.3f}  {t.label_source}")
        for g in r.groups():
            s = r.pooled(g)
            lines.append(f"{m:<6} {'POOLED ' + g:<16} {s.cuts:>5} {s.transitions:>5} {s.tp:>4} "
                         f"{s.precision:>6.3f} {s.recall:>6.3f} {s.f1:>6.3f}")
        if len(r.groups()) > 1:
            s = r.pooled()
            lines.append(f"{m:<6} {'POOLED all':<16} {s.cuts:>5} {s.transitions:>5} {s.tp:>4} "
                         f"{s.precision:>6.3f} {s.recall:>6.3f} {s.f1:>6.3f}")
        lines.append("")
    if report.errors:
        lines.append("takes that failed:")
        lines.extend(f"  {k}: {v}" for k, v in report.errors.items())
    return "\n".join(lines).rstrip("\n") + "\n"


def add_evaluate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("data_dir", help="folder laid out like ../shared/data "
                   "(cmu/, labels/, tsseg4d/)")
    add_method_argument(p, "all")
    p.add_argument("--group", choices=[*GROUPS, "all"], default="cmu",
                   help="which takes: cmu (full-rotation takes, default), tsseg4d "
                        "(four-channel takes) or all (pooled per group and overall)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--params", metavar="FILE",
                   help="detector parameters, TOML or JSON: flat, or one table per method")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    add_profile_argument(p)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "evaluate", help="score the detectors against labelled takes",
        description="Segment every labelled take of DATA_DIR and print precision, recall "
                    "and F1 per take and pooled (counts summed over takes, then divided).")
    add_evaluate_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    methods = methods_of(args.method)
    report = evaluate_dir(args.data_dir, methods, args.group,
                          params_by_method(args.params, methods), progress=not args.no_progress,
                          profile=args.profile)
    if args.json:
        sys.stdout.write(json.dumps(report.as_dict(), indent=2, allow_nan=False) + "\n")
    else:
        sys.stdout.write(format_table(report))
    for key, msg in report.errors.items():
        print(f"rtseg evaluate: {key} not scored: {msg}", file=sys.stderr)
    return 1 if report.errors else 0
