#!/usr/bin/env python3
"""Held-out figures of named behaviour libraries (rtseg.library.behaviours, docs/identity.md).

    python3 benchmarks/library_loto.py mocap6 [DATA_DIR]          # leave-one-take-out
    python3 benchmarks/library_loto.py mocap6 --by-person [DATA_DIR] # leave-one-person-out
    python3 benchmarks/library_loto.py single [DATA_DIR/cmu_single] # leave-one-person-out
    python3 benchmarks/library_loto.py spliced SPLICED_DIR [SOURCE_DIR]   # cmu_single
    python3 benchmarks/library_loto.py fewshot [DATA_DIR] [--seconds S]  # short examples
    python3 benchmarks/library_loto.py --by-person DIR [--n N] [--seed K] [--no-hide] [--truth-cuts]
        [--one-person] [--no-posture]
    (options: --no-reject, --metric model|descriptor, --step S, --window S, --name-after S,
    --claim-margin M,
    --decide-after S, --id-threshold D, --threshold-scale F, --rule W,L,C,
    --first-name S,K, --library-threshold D,
    --posture-weight W, --speed-weight S,
    --params FILE: the live detectors' parameters, e.g. fast)

--by-person DIR: DIR a source folder laid out like ../shared/data/cmu_single, hdm05 or
bandai, or their parent (../shared/data): per source, leave-one-person-out - the library
learned from the other people of the same source names N (default 4) spliced
performances of the held-out person (rtseg.evaluation.names_lopo; seed K, default 0), then again
with each of their behaviours left out of the library in turn (not with --no-hide).  Per
source and pooled: ``known`` (segments of behaviours the library holds: ``accuracy``
named right, ``unknown_rate``, ``wrong_rate``, ``decision_delay_s`` after the change) and
``left_out`` (segments of behaviours missing from the library: ``unknown_rate``); per
source also ``by_person``, the same figures of each held-out person.
``--no-posture``: the performances' sessions are not told their rig's rest geometry, as
IMU suits whose geometry is unknown: names by the model distance alone (what ``rtseg learn
LIB --check`` estimates as "sessions without posture").
``--one-person``: each held-out person named by each other person's library alone (every
ordered pair a fold, keyed "P by O"; rtseg.evaluation.names_lopo, One-person libraries).
``--segments``: every segment in the JSON too.  ``--truth-cuts``:
the segments are the labelled ones - a cut at every labelled change, delivered at that
frame, instead of the live detector's cuts - so the naming is measured apart from where
the detector cuts (names decided ``decide_after_s``, or ``name_after_s``, after the
change).  A source in which nobody can be scored (one person, or nobody with two
behaviours) is one line on stderr naming each person's reason; exit 1 when no source
scored anyone (the JSON is still printed).

mocap6: the three mocap6 takes (13_29, 13_31, 14_14; exercise names); for each take a
library learned from the other two names its live segments (``contrast`` cuts, decided
names as sent).  Also each exercise of the held-out take left out of the library in turn:
its segments must come out ``unknown``.  ``--by-person``: leave-one-person-out instead (the
library of subject 13's takes names subject 14's and the other way round: a person's
takes are named from other people's examples only).
single: cmu_single, per feature profile (BVH takes: unity; AMC: cmu14; 10_04's Daz
skeleton has neither): for each person, a library from the other people's takes of that
profile names the live segments of the person's takes.  Behaviours only this person
performs are not in the library: they must come out ``unknown``.
spliced: spliced performances (benchmarks/splice.py) named by a library learned from the
takes of SOURCE_DIR (a source folder laid out like ../shared/data/cmu_single, hdm05 or
bandai; default cmu_single) of the people NOT in the performance.  Performances of people
SOURCE_DIR does not hold (``benchmarks/splice.py OTHER PERF --kind same``, OTHER another
folder laid out like it) are named by a library of all its people: how names carry to
people the project does not have (docs/identity.md).
fewshot: what ``rtseg learn LIB --take FILE --label NAME --frames A:B`` builds from a few
seconds of each behaviour.  Each mocap6 take is named by a library learned from ONE other
take, each exercise's example cut to its middle ``--seconds`` S (default 4; longer ones
kept whole), so that no behaviour has a second example (``held_out``, and each exercise
left out in turn: ``hidden_names``); and by one-name libraries, each exercise of the other
take alone (``one_name``: that exercise's segments must get its name, every other segment
``unknown``).
``--no-reject``: no null rejection (every segment its nearest name), the ceiling.
``--metric descriptor``: libraries of the earlier descriptor distance (default: model).
``--step S``: example windows every S seconds (default ``rtseg.library.behaviours.DEFAULT_STEP_S``);
``--window S``: example windows S seconds long (default the builder's, 2 s);
``--name-after S``: the tracker's ``name_after_s`` (default: config/live.toml's);
``--decide-after S``, ``--id-threshold D``: its ``decide_after_s`` and ``threshold`` (the
ids, and when a segment is named; defaults: config/live.toml's);
``--claim-margin M``: its ``claim_margin`` (0-1; 0 = exclusive names without claims);
``--threshold-scale F``: its ``name_threshold_scale``, every library's threshold times F
(how strict the names are, docs/identity.md).
``--first-name S,K``: its ``first_name_after_s`` and ``first_name_scale`` (a segment the
library names by K x its threshold S seconds in is decided then); ``--library-threshold
D``: its ``library_threshold`` (the ids' threshold with a library).
``--rule W,L,C``: the decision's margin (``rtseg.library.calibration.decision_excess``:
``MARGIN_WEIGHT``, ``MARGIN_LEVEL``, ``MARGIN_CAP``; ``0,0,1`` the threshold alone) for
this run - what ``benchmarks/names_rule_lopo.py`` chooses among.  ``--posture-weight W``:
the posture distance's weight in the names' distance (``rtseg.library.posture_distance
.WEIGHT``, 2/3); ``--speed-weight S``: the joint speeds' weight in the body descriptors of
the libraries this run learns (``rtseg.library.joint_speed.SPEED_WEIGHT``, 1).
Prints one JSON document; parameters are the library's own (calibrated inside it).
``held_out``: the held-out takes' segments (``unknown_correct`` over those whose behaviour
the library lacks); ``hidden_names``: the segments of each name left out in turn;
``not_known``: both kinds of not-known segments together (``rtseg evaluate --identity``'s
``identity.library.unknown_correct``).  With ``[identity] exclusive_names`` (default) a
name only other behaviour ids of the session hold is sent ``unknown``.
``decision_delay_s`` (per summary): median / p90 seconds from a labelled change to the name
on the wire, over the known segments that start within 1 s of one.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from rtseg.labels.truth import named_truth_labels
from rtseg.labels.takes import find_labelled_takes
from rtseg.evaluation.library import run_folds
from rtseg.library.sources import examples_from_dir
from rtseg.evaluation.online import live_config

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


class _Usage(ValueError):
    """A command-line option that cannot be taken (the message is printed, exit 2)."""


def _pop_number(argv: list[str], flag: str, kind: type, what: str,
                not_positive: str | None = None):
    """The value after ``flag`` in ``argv`` as ``kind`` (a number type, or ``str``; both
    removed), None when absent; ``_Usage`` "FLAG: WHAT" when it is not one (or missing),
    "FLAG: NOT_POSITIVE" when it is <= 0 and ``not_positive`` is given."""
    if flag not in argv:
        return None
    k = argv.index(flag)
    try:
        value = kind(argv[k + 1])
    except (IndexError, ValueError):
        raise _Usage(f"{flag}: {what}") from None
    if not_positive is not None and not value > 0:
        raise _Usage(f"{flag}: {not_positive}")
    del argv[k:k + 2]
    return value


def _identity_settings(cfg) -> dict:
    """The identity tracker's settings a run used, as its JSON document states them."""
    return {"name_after_s": cfg["identity.name_after_s"],
            "decide_after_s": cfg["identity.decide_after_s"],
            "identity_threshold": cfg["identity.threshold"],
            "claim_margin": cfg["identity.claim_margin"],
            "name_threshold_scale": cfg["identity.name_threshold_scale"],
            "first_name_after_s": cfg["identity.first_name_after_s"],
            "first_name_scale": cfg["identity.first_name_scale"],
            "library_threshold": cfg["identity.library_threshold"]}


def _identity_options(cfg, opts: dict) -> None:
    """``--name-after``, ``--decide-after``, ``--id-threshold``, ``--claim-margin``,
    ``--threshold-scale``, ``--first-name`` and ``--library-threshold`` into the session
    configuration ``cfg``."""
    if "--name-after" in opts:
        cfg["identity.name_after_s"] = opts["--name-after"]
    if "--decide-after" in opts:
        cfg["identity.decide_after_s"] = opts["--decide-after"]
    if "--id-threshold" in opts:
        cfg["identity.threshold"] = opts["--id-threshold"]
    if "--claim-margin" in opts:
        cfg["identity.claim_margin"] = opts["--claim-margin"]
    if "--threshold-scale" in opts:
        cfg["identity.name_threshold_scale"] = opts["--threshold-scale"]
    if "--first-name" in opts:
        cfg["identity.first_name_after_s"], cfg["identity.first_name_scale"] = opts["--first-name"]
    if "--library-threshold" in opts:
        cfg["identity.library_threshold"] = opts["--library-threshold"]


def _session_config(opts: dict):
    """The live session configuration a run names with: the shipped one, or ``--params``'
    detector parameters (``fast``: config/fast.toml), identity on, the identity options."""
    cfg, _ = live_config(params=opts.get("--params"))
    cfg["identity.enabled"] = True
    _identity_options(cfg, opts)
    return cfg


def _run_header(protocol: str, t0: float, cfg) -> dict:
    """What every run's JSON document states first: the protocol, its wall time (s), the
    example windows, the identity tracker's and the naming decision's settings."""
    import rtseg.evaluation.library as le
    from rtseg.library.behaviours import DEFAULT_STEP_S, DEFAULT_WINDOW_S
    return {"protocol": protocol, "seconds": round(time.perf_counter() - t0, 1),
            "step_s": le.WINDOWS.get("step_s", DEFAULT_STEP_S),
            "window_s": le.WINDOWS.get("window_s", DEFAULT_WINDOW_S),
            **_identity_settings(cfg), **_naming_settings()}


def _set_rule(text: str) -> None:
    """``--rule WEIGHT,LEVEL,CAP``: the decision's margin (``rtseg.library.calibration``'s
    ``MARGIN_WEIGHT``, ``MARGIN_LEVEL``, ``MARGIN_CAP``) for this run; ``0,0,1`` is the
    threshold alone.  ``_Usage`` when it is not three numbers, the weight below 0 or the
    cap below 1."""
    import rtseg.library.calibration as cal
    try:
        weight, level, cap = (float(v) for v in text.split(","))
    except ValueError:
        raise _Usage("--rule: WEIGHT,LEVEL,CAP (three numbers)") from None
    if not weight >= 0 or not cap >= 1:
        raise _Usage("--rule: the weight must be at least 0 and the cap at least 1")
    cal.MARGIN_WEIGHT, cal.MARGIN_LEVEL, cal.MARGIN_CAP = weight, level, cap


def _set_weights(posture: float | None, speed: float | None) -> None:
    """``--posture-weight W`` (``rtseg.library.posture_distance.WEIGHT``, the posture
    distance's weight in the names' distance) and ``--speed-weight S`` (the joint speeds'
    weight in the body descriptors of the libraries learned in this run,
    ``rtseg.library.joint_speed.SPEED_WEIGHT``); None leaves one as shipped."""
    import rtseg.library.builder as builder
    import rtseg.library.posture_distance as pd
    if posture is not None:
        if not 0.0 < posture <= 1.0:
            raise _Usage("--posture-weight: a number above 0, at most 1")
        pd.WEIGHT = posture
    if speed is not None:
        if not speed >= 0.0:
            raise _Usage("--speed-weight: a number, at least 0")
        builder.SPEED_WEIGHT = speed


def _naming_settings() -> dict:
    """The decision's margin (``--rule``) and the names' distance weights
    (``--posture-weight``, ``--speed-weight``) a run used, as its JSON states them."""
    import rtseg.library.builder as builder
    import rtseg.library.calibration as cal
    import rtseg.library.posture_distance as pd
    return {"decision_rule": {"weight": cal.MARGIN_WEIGHT, "level": cal.MARGIN_LEVEL,
                              "cap": cal.MARGIN_CAP},
            "posture_weight": round(pd.WEIGHT, 6), "speed_weight": builder.SPEED_WEIGHT}


def _progress(msg: str) -> None:
    print(f"  {msg}", file=sys.stderr, flush=True)


def mocap6(data: Path, cfg, by_person: bool = False) -> dict:
    takes = [t for t in find_labelled_takes(data, ("cmu",)) if "mocap6" in t.labels.source]
    names = [t.name for t in takes]
    # a unit: a take, or with by_person a person (a CMU take's subject, "13" of 13_29)
    unit_of = {n: n.split("_")[0] if by_person else n for n in names}
    if by_person and len(set(unit_of.values())) < 2:
        raise ValueError(f"--by-person needs takes of two people, got {sorted(unit_of)}")
    ex = examples_from_dir(data, cfg, takes=names)
    tk = {}
    for lt in takes:
        take = lt.load()
        truth = named_truth_labels(lt, take.n_frames)
        tk[lt.name] = (take, truth)
    units = {u: (lambda e, u=u: unit_of.get(e.take) == u) for u in sorted(set(unit_of.values()))}
    return run_folds(ex, units, tk, unit_of, cfg, True, _progress)


def fewshot(data: Path, cfg, seconds: float) -> dict:
    import dataclasses
    takes = [t for t in find_labelled_takes(data, ("cmu",)) if "mocap6" in t.labels.source]
    names = [t.name for t in takes]
    ex = []
    for e in examples_from_dir(data, cfg, takes=names):
        a, b = e.frames
        n = int(round(seconds * e.frame_rate))
        if b - a > n:
            m = (a + b) // 2
            e = dataclasses.replace(e, frames=(m - n // 2, m - n // 2 + n))
        ex.append(e)
    # every unit names one take and holds one other take's examples (units1: one name of
    # them), so a unit's key is also its take's key
    tk, units, tk1, units1 = {}, {}, {}, {}
    for lt in takes:
        take = lt.load()
        truth = named_truth_labels(lt, take.n_frames)
        for src in names:
            if src == lt.name:
                continue
            k = f"{lt.name} by {src}"
            tk[k] = (take, truth)
            units[k] = (lambda e, s=src: e.take != s)
            for nm in sorted({e.name for e in ex if e.take == src}):
                tk1[f"{k}: {nm}"] = (take, truth)
                units1[f"{k}: {nm}"] = (lambda e, s=src, n=nm: e.take != s or e.name != n)
    doc = run_folds(ex, units, tk, {k: k for k in tk}, cfg, True, _progress)
    one = run_folds(ex, units1, tk1, {k: k for k in tk1}, cfg, False, _progress)
    doc["one_name"] = one["held_out"]
    doc["libraries"] += one["libraries"]
    doc["seconds"] = seconds
    return doc


def single(src: Path, cfg) -> dict:
    from rtseg.evaluation.splice import read_source_index
    from rtseg.drivers.readers import read_take
    rows = read_source_index(src)
    ex = examples_from_dir(src, cfg)
    out = {}
    for profile in sorted({e.profile for e in ex}):
        exp = [e for e in ex if e.profile == profile]
        people = sorted({e.person for e in exp})
        tk, unit = {}, {}
        for r in rows:
            if r.subject in people and any(e.take == r.name for e in exp):
                take = read_take(r.path)
                tk[r.name] = (take, np.array([r.behaviour] * take.n_frames))
                unit[r.name] = r.subject
        units = {p: (lambda e, p=p: e.person == p) for p in people}
        out[profile] = run_folds(exp, units, tk, unit, cfg, False, _progress)
        out[profile]["people"] = people
    return out


def spliced(folder: Path, src: Path, cfg) -> dict:
    from rtseg.core.features import PoseFeatures
    from rtseg.drivers.readers import read_take
    ex = examples_from_dir(src, cfg)
    takes = find_labelled_takes(folder, ("spliced",))
    tk, unit, units = {}, {}, {}
    for lt in takes:
        take = read_take(lt.motion)
        people = sorted(str(p) for p in (take.meta.get("splice") or {}).get("subjects", []))
        names = list(take.meta["frame_label_names"])
        truth = np.array([names[int(i)] for i in take.meta["frame_labels"]])
        if not people:
            raise ValueError(f"{lt.motion}: no subjects in its meta")
        tk[lt.name] = (take, np.asarray(truth, dtype=str))
        unit[lt.name] = lt.name
        prof = PoseFeatures(take.joint_names, take.parents, take.space,
                            profile=cfg["features.profile"] or None).profile
        units[lt.name] = (lambda e, ps=frozenset(people), pr=prof: e.person in ps
                          or e.profile != pr)
    return run_folds(ex, units, tk, unit, cfg, False, _progress)


def by_person_sources(argv: list[str], opts: dict) -> int:
    """``--by-person DIR [--n N] [--seed K] [--no-hide] [--segments] [--one-person]
    [--no-posture]`` (module doc)."""
    import rtseg.evaluation.library as le
    from rtseg.evaluation.names_lopo import lopo_sources
    kw = {"n": 4, "seed": 0}
    try:
        for flag, key in (("--n", "n"), ("--seed", "seed")):
            value = _pop_number(argv, flag, int, "a whole number")
            if value is not None:
                kw[key] = value
        if kw["n"] < 1:
            raise _Usage("--n: at least 1 performance per person")
    except _Usage as exc:
        print(exc, file=sys.stderr)
        return 2
    hide = "--no-hide" not in argv
    segments = "--segments" in argv
    kw["cuts"] = "truth" if "--truth-cuts" in argv else "live"
    kw["one_person"] = "--one-person" in argv
    kw["posture"] = "--no-posture" not in argv
    argv = [a for a in argv if a not in ("--no-hide", "--segments", "--truth-cuts",
                                         "--one-person", "--no-posture")]
    if len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    cfg = _session_config(opts)
    t0 = time.perf_counter()
    try:
        doc = lopo_sources(Path(argv[0]), cfg, hide=hide, progress=_progress,
                           windows=dict(le.WINDOWS), metric=le.METRIC, **kw)
    except (FileNotFoundError, ValueError) as exc:
        print(f"library_loto.py --by-person: {exc}", file=sys.stderr)
        return 2
    if not segments:
        for d in doc["sources"].values():
            d.pop("segments", None)
    for name, d in doc["sources"].items():     # a source nobody in is scored: say why
        if not d["people"]:
            why = "; ".join(f"{p}: {r}" for p, r in sorted(d["skipped"].items())) or "nobody in it"
            print(f"library_loto.py --by-person: {name}: nobody scored ({why})", file=sys.stderr)
    protocol = "leave-one-person-out over source folders" + (
        ", one-person libraries" if kw["one_person"] else "")
    print(json.dumps({**_run_header(protocol, t0, cfg), "performances": kw["n"],
                      "seed": kw["seed"], "hidden_names": hide, "cuts": kw["cuts"],
                      "posture": kw["posture"],
                      **doc}, indent=1, default=str))
    return 0 if any(d["people"] for d in doc["sources"].values()) else 1


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    if "--no-reject" in argv:              # every segment gets its nearest name
        import rtseg.evaluation.library as le
        le.NO_REJECT = True
        argv.remove("--no-reject")
    if "--metric" in argv:                 # the libraries' distance (rtseg.library.behaviours.METRICS)
        import rtseg.evaluation.library as le
        from rtseg.library.behaviours import METRICS
        k = argv.index("--metric")
        if k + 1 >= len(argv) or argv[k + 1] not in METRICS:
            print(f"--metric: one of {', '.join(METRICS)}", file=sys.stderr)
            return 2
        le.METRIC = argv[k + 1]
        del argv[k:k + 2]
    opts = {}
    try:
        rule = _pop_number(argv, "--rule", str, "WEIGHT,LEVEL,CAP (three numbers)")
        if rule is not None:
            _set_rule(rule)
        _set_weights(_pop_number(argv, "--posture-weight", float, "a number above 0, at most 1"),
                     _pop_number(argv, "--speed-weight", float, "a number, at least 0"))
        params = _pop_number(argv, "--params", str, "a detector parameter file (or 'fast')")
        if params is not None:
            opts["--params"] = params
        for flag in ("--step", "--window", "--name-after", "--seconds", "--decide-after"):
            value = _pop_number(argv, flag, float, "seconds, a number", "seconds, > 0")
            if value is not None:
                opts[flag] = value
        value = _pop_number(argv, "--id-threshold", float, "a distance, a number", "> 0")
        if value is not None:
            opts["--id-threshold"] = value
        value = _pop_number(argv, "--threshold-scale", float, "a number", "> 0")
        if value is not None:
            opts["--threshold-scale"] = value
        value = _pop_number(argv, "--library-threshold", float, "a distance, a number", "> 0")
        if value is not None:
            opts["--library-threshold"] = value
        first = _pop_number(argv, "--first-name", str, "S,K: seconds and a factor")
        if first is not None:
            try:
                after, scale = (float(v) for v in first.split(","))
            except ValueError:
                raise _Usage("--first-name: S,K - seconds and a factor, e.g. 1.5,0.9") from None
            if not (after >= 0 and 0 < scale <= 1):
                raise _Usage("--first-name: S,K with S >= 0 seconds and K in (0, 1]")
            opts["--first-name"] = (after, scale)
        margin = _pop_number(argv, "--claim-margin", float, "a number from 0 to 1")
        if margin is not None:
            if not 0.0 <= margin <= 1.0:
                raise _Usage("--claim-margin: a number from 0 to 1")
            opts["--claim-margin"] = margin
    except _Usage as exc:
        print(exc, file=sys.stderr)
        return 2
    import rtseg.evaluation.library as le
    if "--step" in opts:
        le.WINDOWS["step_s"] = opts["--step"]
    if "--window" in opts:
        le.WINDOWS["window_s"] = opts["--window"]
    by_person = "--by-person" in argv
    if by_person:
        argv.remove("--by-person")
    if by_person and argv and argv[0] not in ("mocap6", "single", "spliced", "fewshot"):
        return by_person_sources(argv, opts)
    if not argv or argv[0] not in ("mocap6", "single", "spliced", "fewshot"):
        print(__doc__, file=sys.stderr)
        return 2
    cfg = _session_config(opts)
    t0 = time.perf_counter()
    if argv[0] in ("mocap6", "fewshot"):
        data = Path(argv[1]) if len(argv) > 1 else DATA
        try:
            found = [t.name for t in find_labelled_takes(data, ("cmu",))
                     if "mocap6" in t.labels.source]
        except FileNotFoundError as exc:
            print(f"library_loto.py {argv[0]}: {exc}", file=sys.stderr)
            return 2
        if len(found) < 2:
            print(f"library_loto.py {argv[0]}: {data} holds {len(found)} mocap6-labelled "
                  f"take(s) (cmu/*.amc with labels/mocap6/TAKE.txt); leave-one-take-out "
                  f"needs two", file=sys.stderr)
            return 2
    try:
        if argv[0] == "mocap6":
            doc = mocap6(Path(argv[1]) if len(argv) > 1 else DATA, cfg, by_person)
        elif argv[0] == "fewshot":
            doc = fewshot(Path(argv[1]) if len(argv) > 1 else DATA, cfg,
                          opts.get("--seconds", 4.0))
        elif argv[0] == "single":
            doc = single(Path(argv[1]) if len(argv) > 1 else DATA / "cmu_single", cfg)
        elif len(argv) < 2:
            print("library_loto.py spliced: give SPLICED_DIR (benchmarks/splice.py output)",
                  file=sys.stderr)
            return 2
        else:
            doc = spliced(Path(argv[1]), Path(argv[2]) if len(argv) > 2 else DATA / "cmu_single",
                          cfg)
    except (FileNotFoundError, ValueError) as exc:
        print(f"library_loto.py {argv[0]}: {exc}", file=sys.stderr)
        return 2
    doc = {**_run_header(argv[0] + (" by person" if by_person else ""), t0, cfg), **doc}
    print(json.dumps(doc, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
