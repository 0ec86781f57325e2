"""``rtseg learn LIB``: build (or extend) a named behaviour library from labelled takes.

    rtseg learn LIB --take FILE --label NAME [--frames A:B] [--skeleton ASF] ...
    rtseg learn LIB --take SESSION_DIR --segment K --label NAME ...   # a recorded segment
    rtseg learn LIB --from DATA_DIR [--person S ...] [--exclude-person S ...]
    rtseg learn LIB --show                      # what LIB holds; nothing learned
    rtseg learn LIB --check [--json]            # how it would name a performer it lacks
    rtseg learn LIB --check --threshold-scales 0.8,1.5   # ... at other strictnesses
    (options: --step S, --profile NAME, --threshold D, --new, --config FILE)

Learning an example the library already holds (the same motion: its content key,
``rtseg.library.sources.motion_key``) adds nothing ("N already in the library"); when
nothing is new (examples too short to give a window are noted, not new) the file is left
as it was and the command succeeds.  ``--take`` starts an example; the ``--label``, ``--frames`` (take frames [A, B), 0-based)
or ``--segment`` (of a session recording, ``rtseg live --record DIR``: segment K as the
session numbered it) and ``--skeleton`` after it belong to it.  ``--from``: every labelled take of a folder
(``rtseg.library.examples.examples_from_dir``).  ``--check``: each person of LIB named by a
library of its other people (``rtseg.library.self_check``): what a performer the library
has never seen can expect, with posture and without; nothing learned.  An existing LIB is extended (its examples
kept, and its window step) unless ``--new``.  ``--step``: example windows start every S
seconds (default ``rtseg.library.behaviours.DEFAULT_STEP_S``, 0.5).  The library is JSON (``rtseg.library.behaviours``); ``rtseg live
--behaviours LIB`` names segments with it.  Exit 2 with one line on bad input.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from rtseg.library.calibration import MARGIN_CAP
from rtseg.library.file import save as save_library


class _TakeAction(argparse.Action):
    """--take / --label / --frames / --skeleton grouped per --take, in order."""

    def __call__(self, parser: Any, ns: argparse.Namespace, value: Any,
                 option: str | None = None) -> None:
        takes = getattr(ns, "takes", None) or []
        if self.dest == "take":
            takes.append({"take": value})
        else:
            if not takes:
                parser.error(f"{option} must follow a --take")
            if self.dest in takes[-1]:
                parser.error(f"{option} given twice for --take {takes[-1]['take']}")
            takes[-1][self.dest] = value
        ns.takes = takes


def parse_frames(text: str) -> tuple[int, int]:
    """``A:B`` -> (A, B), 0 <= A < B."""
    try:
        a, b = (int(v) for v in text.split(":"))
    except ValueError:
        raise ValueError(f"--frames {text!r}: expected A:B (take frames, 0-based, B excluded)") from None
    if not 0 <= a < b:
        raise ValueError(f"--frames {text!r}: needs 0 <= A < B")
    return a, b


def recorded_segment(t: dict[str, Any]) -> int | None:
    """K of ``--segment K`` of a ``--take`` (None without it); the take must be a session
    recording."""
    from rtseg.recording.reader import is_session_dir, sessions_inside
    if t.get("segment") is None:
        return None
    if t.get("frames"):
        raise ValueError(f"--take {t['take']}: give --frames or --segment, not both")
    if not is_session_dir(t["take"]):
        raise ValueError(f"--take {t['take']}: --segment needs a session recording "
                         f"(rtseg live --record DIR)" + sessions_inside(t["take"]))
    try:
        return int(t["segment"])
    except ValueError:
        raise ValueError(f"--segment {t['segment']!r}: a segment number (0, 1, ...)") from None


#: ``rtseg learn`` says a behaviour "may be confused" with its nearest other name when at
#: least this share of its windows lie as near or nearer another name than its own other
#: examples (a display choice; naming does not use it), or - no second example - when that
#: name lies within the threshold
CONFUSED_SHARE = 0.25
#: ``describe`` adds a note to the people line when another person's examples lie at least
#: this many times as far as the same person's (a display choice; naming does not use it):
#: bandai's two actors, two styles, 2.6; hdm05's three people 1.25, cmu_single's 1.2
#: (model distance; docs/identity.md, Limits)
SPREAD_NOTE = 2.0


def _rule_text(lib: Any, threshold: float, ratio: float) -> str:
    """The decision a library names by (``rtseg.library.calibration.decision_excess``)."""
    if getattr(lib, "calibrated_threshold", False):
        return (f"unknown beyond distance {threshold:.3f}, moved by the margin to the next "
                f"name (ratio {ratio:.2f}; at most {MARGIN_CAP:g} x)")
    return f"unknown beyond distance {threshold:.3f} or ratio {ratio:.2f} to the next name"


def describe(lib: Any, path: Path, sources: bool = False) -> list[str]:
    """Lines saying what a library holds: its windows and profile, the rejection rule and
    where it comes from, and per behaviour its example count; with ``sources`` also its
    distance and windows, and every example's source, take frames and person."""
    given = lib.calibration.get("threshold_given")
    calibrated = lib.calibration.get("calibrated", True)
    by_name: dict[str, list[dict[str, Any]]] = {}
    for e in lib.examples:
        by_name.setdefault(e["name"], []).append(e)
    out = [f"{path}: {len(by_name)} behaviours, {len(lib.examples)} examples, "
           f"{len(lib.names)} windows; profile {lib.profile} ({lib.dims} dims); "
           + _rule_text(lib, lib.threshold, lib.ratio)
           + (" (given)" if given else " (calibrated)" if calibrated else " (default)")]
    if getattr(lib, "names_by_posture", False):
        out.append("  with posture (sessions whose rig geometry is known): "
                   + _rule_text(lib, lib.posture_rule["threshold"], lib.posture_rule["ratio"]))
    elif getattr(lib, "has_posture", False):
        out.append("  posture kept, not used until a behaviour has a second example")
    spread = lib.calibration.get("people")
    if spread and spread.get("ratio"):
        post = (lib.calibration.get("posture") or {}).get("people") or {}
        out.append(f"  another person's examples lie {spread['ratio']:.2f} x as far as the "
                   f"same person's other examples (nearest same-name window, median "
                   f"{spread['other_person']:.2f} against {spread['same_person']:.2f}"
                   + (f"; with posture {post['ratio']:.2f} x" if post.get("ratio") else "")
                   + ")" + (": the people or styles differ more than one person's takes; "
                            "a new performer is named best from examples near their own style"
                            if spread["ratio"] >= SPREAD_NOTE else ""))
    if sources:
        out.append(f"  {lib.metric} distance, windows of {lib.window_s:g} s every "
                   f"{lib.step_s:g} s, {lib.frame_rate:g} Hz")
    near = lib.calibration.get("nearest_other")
    if near is None and len(lib.names):     # a file learned before it was kept: work it out
        import copy
        probe = copy.copy(lib)
        probe.calibrate()
        near = probe.calibration.get("nearest_other")
    near = near or {}
    # a known case is another example's window: another person's when the examples name
    # several people (rtseg.library.behaviours.Library.calibrate), else another take or recording's
    people = {str(e["person"]) for e in lib.examples if e.get("person")}
    second = "second example" + (" from another person" if len(people) > 1 else "")
    for k in sorted(by_name):
        nb = near.get(k)
        close = ""
        if nb:
            same, share = nb.get("same"), nb.get("nearer_other")
            close = (f"; nearest other name {nb['name']} at {nb['distance']:.2f}"
                     + (f" (its other examples at {same:.2f}; {share:.0%} of its windows "
                        f"lie as near another name)" if share is not None else
                        f" (no {second}: how near a new performance of it lies is "
                        f"not known, add one)"))
            if (share is not None and share >= CONFUSED_SHARE) or (
                    same is None and nb["distance"] <= lib.threshold):
                close += ": may be confused"
        out.append(f"  {k}: {len(by_name[k])} example(s){close}")
        for e in by_name[k] if sources else ():
            a, b = (e.get("frames") or [None, None])[:2]
            span = f" frames {a}:{b}" if a is not None else ""
            who = f", person {e['person']}" if e.get("person") else ""
            out.append(f"    {e.get('source', '?')}{span}{who}")
    return out


def grouped_notes(notes: list[str], show: int = 4) -> list[str]:
    """``notes`` with the takes left out for one reason ("TAKE: left out: WHY") in one line
    each ("N takes left out (A, B, ... and M more): WHY"), in the order first met."""
    out: list[str] = []
    by_why: dict[str, list[str]] = {}
    for n in notes:
        take, sep, why = n.partition(": left out: ")
        if not sep:
            out.append(n)
            continue
        if why not in by_why:
            by_why[why] = []
            out.append(why)
        by_why[why].append(take)
    lines = []
    for n in out:
        takes = by_why.get(n)
        if takes is None:
            lines.append(n)
        elif len(takes) == 1:
            lines.append(f"{takes[0]}: left out: {n}")
        else:
            more = f" and {len(takes) - show} more" if len(takes) > show else ""
            lines.append(f"{len(takes)} takes left out ({', '.join(takes[:show])}{more}): {n}")
    return lines


def _scales(text: str) -> list[float]:
    """``--threshold-scales F,F,...``: positive numbers (argparse's error otherwise)."""
    try:
        out = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        out = []
    if not out or not all(math.isfinite(f) and f > 0 for f in out):
        raise argparse.ArgumentTypeError(f"positive numbers separated by commas, got {text!r}")
    return out


def check_library(lib: Any, path: Path, as_json: bool,
                  threshold_scales: tuple[float, ...] = ()) -> int:
    """``rtseg learn LIB --check``: each person named by a library of the others
    (``rtseg.library.self_check.check``), by the distance of sessions with posture when the
    library names by it and by the model distance alone, and at each operator's scale of
    ``threshold_scales`` besides 1; lines, or one JSON document."""
    import json
    from rtseg.library.self_check import check_lines, checks
    results = checks(lib, (True, False) if lib.names_by_posture else (False,),
                     threshold_scales)
    if as_json:
        print(json.dumps({"library": str(path), "window_s": lib.window_s,
                          "checks": [r.as_dict() for r in results]}, indent=1))
    else:
        print("\n".join([f"{path}:"] + check_lines(lib, results)))
    return 0


def run(args: argparse.Namespace) -> int:
    from rtseg.library.behaviours import DEFAULT_STEP_S
    from rtseg.library.file import load
    from rtseg.library.examples import example_of_take, learn, learnable, unique_examples
    from rtseg.library.sources import examples_from_dir
    from rtseg.evaluation.online import live_config
    takes = getattr(args, "takes", None) or []
    if args.json and not args.check:
        raise ValueError("--json goes with --check")
    if args.threshold_scales and not args.check:
        raise ValueError("--threshold-scales goes with --check")
    if args.show or args.check:
        flag = "--show" if args.show else "--check"
        if takes or args.from_dir or args.new or (args.show and args.check):
            raise ValueError(f"{flag} only reads LIB: give no --take, --from, --new"
                             + (" or --check" if args.show else "") + " with it")
        lib = load(args.library)
        if args.show:
            print("\n".join(describe(lib, Path(args.library), sources=True)))
            return 0
        return check_library(lib, Path(args.library), args.json,
                             tuple(args.threshold_scales or ()))
    if not takes and not args.from_dir:
        raise ValueError("nothing to learn from: give --take FILE --label NAME or --from DATA_DIR")
    cfg, _ = live_config(args.config)
    if args.profile:             # the examples' features are computed with that profile
        have = cfg["features.profile"]
        if have and have != args.profile:
            raise ValueError(f"--profile {args.profile}: the configuration's [features] "
                             f"profile is {have!r}")
        cfg["features.profile"] = args.profile
    examples = []
    for t in takes:
        if not t.get("label"):
            raise ValueError(f"--take {t['take']}: needs --label NAME")
        frames = parse_frames(t["frames"]) if t.get("frames") else None
        examples.append(example_of_take(t["take"], t["label"], cfg, frames, t.get("skeleton"),
                                        segment=recorded_segment(t)))
    src_notes: list[str] = []
    if args.from_dir:
        if not Path(args.from_dir).is_dir():
            raise ValueError(f"--from {args.from_dir}: no such folder")
        found = examples_from_dir(args.from_dir, cfg, people=args.person or None,
                                  notes=src_notes)
        drop = set(args.exclude_person or [])
        examples += [e for e in found if e.person not in drop]
    old = None
    path = Path(args.library)
    if path.exists() and not args.new:
        old = load(path)
    step = args.step if args.step is not None else (old.step_s if old else DEFAULT_STEP_S)
    if not step > 0:
        raise ValueError(f"--step {step:g}: seconds, > 0")
    if old is not None and abs(step - old.step_s) > 1e-9:
        raise ValueError(f"--step {step:g}: {path} has windows every {old.step_s:g} s; "
                         f"give --new to learn it again with another step")
    known = {str(e["key"]): str(e["name"]) for e in (old.examples if old else [])
             if e.get("key")}
    examples, repeated = unique_examples(examples, known)
    for e in repeated:
        was = known.get(e.key)
        if was is not None and was != e.name:
            src_notes.append(f"{e.take} [{e.frames[0]}:{e.frames[1]}) {e.name}: already in "
                             f"the library as {was!r}; not added again")
    held = sum(e.key in known for e in repeated)
    short: list[str] = []
    if old is not None:          # too short to learn: noted here, so they are not "new"
        examples, short = learnable(examples, step_s=step)
        src_notes += short
    for n in grouped_notes(src_notes):
        print(f"rtseg learn: note: {n}", file=sys.stderr)
    if held:
        print(f"rtseg learn: {held} already in the library", file=sys.stderr)
    if old is not None and not examples:
        if short and not held:      # as for a new library: nothing given could be learned
            raise ValueError(f"no example long enough to learn from (notes above); {path} "
                             f"is unchanged")
        if args.threshold is not None:
            raise ValueError(f"nothing new to learn: {held} already in the library "
                             f"(--threshold applies to a library being learned)")
        print("\n".join(describe(old, path)))
        return 0
    if not examples:
        raise ValueError("no labelled examples to learn from")
    lib, notes = learn(examples, args.profile or (old.profile if old else None), step_s=step)
    if old is not None:
        lib = old.merged(lib)
    if args.threshold is not None:
        lib.threshold = float(args.threshold)
        if lib.names_by_posture:
            lib.posture_rule["threshold"] = float(args.threshold)
        lib.calibration["threshold_given"] = True
    for n in notes:
        print(f"rtseg learn: note: {n}", file=sys.stderr)
    save_library(lib, path)
    given = lib.calibration.get("threshold_given")
    calibrated = lib.calibration.get("calibrated", True)
    print("\n".join(describe(lib, path)))
    if not given and not calibrated:
        print("rtseg learn: note: no behaviour has a second example (another take or "
              "recording), so nothing tells how near a new performance lies: the threshold "
              "is the default; add a second example of a behaviour to calibrate it, or give "
              "--threshold D", file=sys.stderr)
    elif not given:
        people = {str(e.get("person") or "") for e in lib.examples}
        if len(people) > 1 and "" not in people:     # what --check needs
            print(f"rtseg learn: note: how it would name a performer it has never seen: "
                  f"rtseg learn {path} --check", file=sys.stderr)
        if len(people) == 1 and "" not in people:
            print(f"rtseg learn: note: every example is of one person ({people.pop()}): "
                  "the threshold is calibrated on that person's other takes, which lie "
                  "nearer each other than another performer's do; a session judges a "
                  "performer whose segments lie farther by their own median distance (the "
                  "performer's scale), which names more of them but also more behaviours "
                  "the library lacks; add examples from a second person", file=sys.stderr)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "learn", help="build a named behaviour library from labelled takes",
        description="Build or extend a behaviour library (JSON) from labelled takes, for "
                    "'rtseg live --behaviours LIB'.  Segments unlike every example are "
                    "named 'unknown'.")
    p.add_argument("library", metavar="LIB", help="library file (created, or extended)")
    p.add_argument("--take", action=_TakeAction, metavar="FILE",
                   help="a take holding an example (repeatable; .amc needs --skeleton "
                        "unless SS.asf lies beside it)")
    p.add_argument("--label", action=_TakeAction, metavar="NAME",
                   help="behaviour name of the preceding --take")
    p.add_argument("--frames", action=_TakeAction, metavar="A:B",
                   help="take frames [A, B) of the preceding --take (default: all but rest "
                        "frames at the ends)")
    p.add_argument("--segment", action=_TakeAction, metavar="K",
                   help="segment K of the preceding --take, a session recording (rtseg live "
                        "--record DIR): its frames from the session's recorded cuts, as the "
                        "console numbered them")
    p.add_argument("--skeleton", action=_TakeAction, metavar="ASF",
                   help="skeleton of the preceding --take")
    p.add_argument("--from", dest="from_dir", metavar="DATA_DIR",
                   help="learn every labelled take of a folder: a source folder laid out "
                        "like cmu_single, hdm05 or bandai (index.tsv), a folder of such "
                        "folders, or ../shared/data (also cmu86 names, mocap6 exercises)")
    p.add_argument("--person", action="append", metavar="S",
                   help="with --from: only takes of subject S (repeatable)")
    p.add_argument("--exclude-person", action="append", metavar="S",
                   help="with --from: leave out subject S (repeatable)")
    p.add_argument("--profile", metavar="NAME",
                   help="learn with this feature profile (rtseg.core.profiles: canonical, "
                        "cmu14, ...): takes whose rig cannot give it are left out with a note; "
                        "default: the configuration's ([features] profile), else each rig's "
                        "own, and the most common among the examples is kept")
    p.add_argument("--threshold", type=float, metavar="D",
                   help="unknown beyond this distance (default: calibrated on the library)")
    p.add_argument("--step", type=float, metavar="S",
                   help="example windows (2 s) start every S seconds (default 0.5; an "
                        "extended library keeps its own)")
    p.add_argument("--new", action="store_true", help="replace LIB instead of extending it")
    p.add_argument("--show", action="store_true",
                   help="print what LIB holds (behaviours, examples and where they came "
                        "from, the rejection rule) and learn nothing")
    p.add_argument("--check", action="store_true",
                   help="name each person of LIB by a library of its other people: what a "
                        "performer it has never seen can expect (known behaviours named "
                        "right / unknown / wrong, missing ones unknown); learn nothing")
    p.add_argument("--threshold-scales", type=_scales, metavar="F,F,...",
                   help="with --check: the pooled figures also at these factors of the "
                        "threshold ([identity] name_threshold_scale; above 1 more names, "
                        "more of them wrong), e.g. 0.8,1.25,1.5,2")
    p.add_argument("--json", action="store_true", help="with --check: one JSON document")
    p.add_argument("--config", metavar="FILE", help="session configuration (features, "
                   "calibration; default config/live.toml)")
    p.set_defaults(func=run, takes=None)
