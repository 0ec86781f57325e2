"""Scoring live behaviour identities against human labels (``rtseg evaluate --online
--identity``).

Per take: the take goes frame by frame through the live ``Pipeline`` with its
``IdentityTracker`` (``rtseg.identity.tracker``), exactly as ``rtseg live`` runs it; the frame
labels are the ids the tracker *sent*: each segment's decided id from its boundary on
(``decided``, the headline figure), and with the corrections applied (``corrected``).
Nothing is relabelled after the fact.  They are compared with the human labels per frame:

- cmu86 ranges (``labels/cmu86_transitions.txt``): the behaviour names, segment k being
  the frames after the previous ``mid`` up to its own ``mid``;
- mocap6 (``labels/mocap6``): the exercise number of each 12-frame block;
- tsseg4d: the CSV's own per-frame label column.

Scores: adjusted Rand index and normalised mutual information (scikit-learn), per take and
pooled over takes (the takes' frames concatenated, each take's ids kept apart since ids
are per session).

A given library (``--behaviours LIB``, JSON ``identity.named``): the live loop names every
segment with it; per segment the name sent at its decision against the behaviour covering
most of the segment (``rtseg.evaluation.library.named_summary``).

Named libraries (``library_loto``, JSON ``identity.library``): leave-one-take-out over the
mocap6 takes among those evaluated - a library learned from the other takes names each
live segment (``rtseg.evaluation.library``); accuracy and unknown rate over the segments.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from rtseg.identity.tracker import IdentityTracker
from rtseg.labels.takes import MOCAP6_BLOCK, LabelledTake, read_frame_label_column, _int_tokens


def truth_labels(lt: LabelledTake, n_frames: int) -> np.ndarray:
    """Per-frame human behaviour labels of a labelled take, as strings (see module doc)."""
    src = lt.labels.source
    if lt.group == "tsseg4d" or (lt.labels.kind == "tolerance" and "column" in src):
        if str(lt.motion).lower().endswith(".csv"):
            lab = read_frame_label_column(lt.motion)
            return _fit_len(np.array([str(v) for v in lab], dtype=object), n_frames)
    if "mocap6" in src:
        path = lt.motion.parent.parent / "labels" / "mocap6" / f"{lt.name}.txt"
        vals = _int_tokens(path, path.read_text(encoding="utf-8-sig"))
        lab = np.repeat(vals, MOCAP6_BLOCK)
        return _fit_len(np.array([str(v) for v in lab], dtype=object), n_frames)
    tr = lt.transitions
    if not tr:
        return np.array(["?"] * n_frames, dtype=object)
    out = np.empty(n_frames, dtype=object)
    prev = 0
    for t in tr:
        out[prev:t.mid + 1] = t.before or f"s{prev}"
        prev = t.mid + 1
    out[prev:] = tr[-1].after or f"s{prev}"
    return out


def named_truth_labels(lt: LabelledTake, n_frames: int) -> np.ndarray:
    """``truth_labels`` with mocap6 exercise numbers as their names (``Jog``, ...): the
    names a behaviour library learned from the labelled takes holds."""
    from rtseg.library.examples import MOCAP6_NAMES
    return np.array([MOCAP6_NAMES.get(str(v), str(v)) for v in truth_labels(lt, n_frames)])


def _fit_len(a: np.ndarray, n: int) -> np.ndarray:
    if len(a) >= n:
        return a[:n]
    return np.concatenate([a, np.repeat(a[-1:], n - len(a))])


@dataclass
class IdentityRun:
    """What the live loop sent on one take."""
    decided: np.ndarray        # per-frame ids (decisions only)
    corrected: np.ndarray      # per-frame ids with corrections applied
    tracker: IdentityTracker
    cut_frames: list[int]


def run_identity(take: Any, config: Any, library: Any = None) -> IdentityRun:
    """Replay ``take`` through the live pipeline (as ``rtseg.evaluation.online.live_cuts``) with
    identity on; the ids sent per frame.  ``library``: a ``rtseg.library.behaviours.Library`` naming
    the segments (``tracker.history`` carries the names)."""
    from rtseg.live.pipeline import Pipeline
    cfg = config
    if not cfg["identity.enabled"]:
        cfg = type(config)({k: dict(v) for k, v in config.values.items()}, config.origin,
                           dict(config.detector_params))
        cfg["identity.enabled"] = True
    n, fr = take.n_frames, float(take.frame_rate)
    pipe = Pipeline(take.joint_names, take.parents, take.space, fr, cfg)
    tracker = pipe.identity
    if library is not None:
        tracker.library = library
    valid = take.valid if take.valid is not None else np.ones((n, take.n_joints), dtype=bool)
    cuts: list[int] = []
    for i in range(n):
        for c in pipe.process(i, take.quats[i], valid[i], i, i / fr, 0, i / fr):
            if c.cut.method == tracker.method:
                cuts.append(int(c.boundary))
    return IdentityRun(tracker.frame_labels(n), tracker.frame_labels(n, corrected=True),
                       tracker, cuts)


def replay_session_identities(directory: str, config: Any) -> IdentityTracker:
    """The identities the live loop makes on a recorded session folder, offline: every
    recorded frame with its sequence number, receive and source time through the
    ``Pipeline`` (as ``rtseg.live.pipeline.replay_session``) with identity on; the tracker
    (``history``: every message in order)."""
    from rtseg.live.pipeline import Pipeline
    from rtseg.recording import read_session
    cfg = config
    if not cfg["identity.enabled"]:
        cfg = type(config)({k: dict(v) for k, v in config.values.items()}, config.origin,
                           dict(config.detector_params))
        cfg["identity.enabled"] = True
    tk = read_session(directory)
    m = tk.meta
    seq, recv, src = m["seq"], m["recv_time"], m["source_time"]
    pipe = Pipeline(tk.joint_names, tk.parents, tk.space, tk.frame_rate, cfg)
    for i in range(tk.n_frames):
        pipe.process(i, tk.quats[i], tk.valid[i], None if seq[i] < 0 else int(seq[i]),
                     float(recv[i]), 0, None if not np.isfinite(src[i]) else float(src[i]))
    return pipe.identity


def scores(truth: np.ndarray, pred: np.ndarray) -> dict[str, float]:
    """{"ari", "nmi"} of per-frame labels."""
    from sklearn.metrics import adjusted_rand_score, normalized_mutual_info_score
    t = np.asarray([str(v) for v in truth])
    return {"ari": float(adjusted_rand_score(t, pred)),
            "nmi": float(normalized_mutual_info_score(t, pred))}


def pooled_scores(pairs: Sequence[tuple[str, np.ndarray, np.ndarray]]) -> dict[str, float]:
    """ARI/NMI over the concatenated frames of (take name, truth, pred), ids kept per take."""
    if not pairs:
        return {"ari": float("nan"), "nmi": float("nan")}
    t = np.concatenate([np.array([f"{k}:{v}" for v in tr]) for k, tr, _ in pairs])
    p = np.concatenate([np.array([f"{k}:{v}" for v in pr]) for k, _, pr in pairs])
    return scores(t, p)


def library_fits(take: Any, library: Any, config: Any) -> bool:
    """True when ``take``'s live features (the configuration's profile) are the library's
    profile and dims."""
    from rtseg.core.features import PoseFeatures
    f = PoseFeatures(take.joint_names, take.parents, take.space,
                     profile=config["features.profile"] or None)
    return (f.profile, f.dim) == (library.profile, library.dims)


def evaluate_identity(takes: Sequence[LabelledTake], config: Any,
                      progress: Any = None, library: Any = None) -> dict[str, Any]:
    """``{"pooled": {ari, nmi}, "groups": {group: {ari, nmi}}, "takes": {name: {...}}}``
    for the causal identities the live loop sends on each take (see module docstring).
    Take keys are ``group/name`` when a name occurs in two groups.  With ``library``
    (``rtseg.library.behaviours.Library``) the live loop names the segments too and ``"named"`` is
    added (``rtseg.evaluation.library.named_summary``: pooled, per take in ``takes[k]["named"]``,
    the truth of a segment the behaviour of most of its frames); takes whose features are
    not the library's profile run without it and are listed in ``named["skipped_takes"]``."""
    from rtseg.evaluation.library import named_segments, named_summary
    names = [t.name for t in takes]
    per: dict[str, Any] = {}
    pairs: dict[str, list] = {}
    after_by: dict[str, list[float]] = {}     # decision delays after the transitions, s
    rows_all: list[Any] = []
    skipped: list[str] = []
    for lt in takes:
        key = lt.name if names.count(lt.name) == 1 else f"{lt.group}/{lt.name}"
        if progress is not None:
            progress.step(f"identity {key}")
        take = lt.load()
        lib = library if library is not None and library_fits(take, library, config) else None
        if library is not None and lib is None:
            skipped.append(key)
        run = run_identity(take, config, lib)
        truth = truth_labels(lt, take.n_frames)
        st = run.tracker.stats
        after = decision_delays_after(run.tracker.history, take.frame_rate,
                                      [t.mid for t in lt.transitions])
        per[key] = {"group": lt.group, **scores(truth, run.decided),
                    "corrected": scores(truth, run.corrected),
                    "segments": st.segments, "behaviours": st.new_behaviours,
                    "corrections": st.corrections, "true_behaviours": len(set(truth)),
                    "decision_delay_s": _delays(run, take.frame_rate, after)}
        if lib is not None:
            rows = named_segments(run, take, named_truth_labels(lt, take.n_frames), lib, key)
            per[key]["named"] = named_summary(rows)
            rows_all += rows
        pairs.setdefault(lt.group, []).append((key, truth, run.decided))
        after_by.setdefault(lt.group, []).extend(after)
    allp = [p for g in pairs.values() for p in g]
    doc = {"pooled": {**pooled_scores(allp),
                      "decision_delay_s": delay_summary(
                          [x for v in after_by.values() for x in v])},
           "groups": {g: {**pooled_scores(v), "decision_delay_s": delay_summary(after_by[g])}
                      for g, v in pairs.items()},
           "takes": per}
    if library is not None:
        doc["named"] = {**named_summary(rows_all), "skipped_takes": skipped}
    return doc


def library_loto(takes: Sequence[LabelledTake], config: Any) -> dict[str, Any] | None:
    """Named libraries, leave-one-take-out over the mocap6 takes among ``takes`` (shared
    exercise names): ``{accuracy, unknown_rate, unknown_correct, known_segments,
    unknown_segments, takes}`` (``rtseg.evaluation.library``); ``unknown_correct`` over the
    ``unknown_segments``: the segments of exercises the other takes lack, and each
    exercise of the held-out take also left out of its library in turn - the share named
    ``unknown``.  None with fewer than two."""
    from rtseg.evaluation.library import run_folds
    from rtseg.library.examples import Example, take_rows
    m6 = [t for t in takes if "mocap6" in t.labels.source]
    if len(m6) < 2:
        return None
    from rtseg.library.examples import label_runs
    examples: list[Example] = []
    tk: dict[str, Any] = {}
    for lt in m6:
        take = lt.load()
        truth = named_truth_labels(lt, take.n_frames)
        X, index, profile = take_rows(take, config)
        for a, b, name in label_runs(truth):
            examples.append(Example(name, lt.name, lt.name.split("_")[0], X, index, (a, b),
                                    profile, float(take.frame_rate)))
        tk[lt.name] = (take, truth)
    units = {n: (lambda e, n=n: e.take == n) for n in tk}
    res = run_folds(examples, units, tk, {n: n for n in tk}, config, hide_names=True)
    not_known = res["not_known"]
    return {**res["held_out"], "unknown_correct": not_known["unknown_correct"],
            "unknown_segments": not_known["unknown_segments"], "takes": sorted(tk),
            "protocol": "leave-one-take-out"}


def decision_delays_after(history: Sequence[Any], frame_rate: float,
                          mids: Sequence[int]) -> list[float]:
    """For each decision (``IdentityDecision``, not a correction, not segment 0) whose
    segment boundary lies within 1 s of a labelled transition mid: decision frame - that
    mid, in seconds."""
    mids_a = np.asarray(mids, dtype=np.int64)
    out: list[float] = []
    if not len(mids_a):
        return out
    for m in history:
        if m.correction or m.segment == 0:
            continue
        j = int(np.argmin(np.abs(mids_a - m.boundary)))
        if abs(int(mids_a[j]) - m.boundary) <= frame_rate:
            out.append((m.decided_frame - int(mids_a[j])) / frame_rate)
    return out


def delay_summary(after: Sequence[float]) -> dict[str, float | int | None]:
    """Median and p90 (s) of decision delays after the labelled transitions, and how many."""
    return {"after_transition_median": round(float(np.median(after)), 3) if after else None,
            "after_transition_p90": round(float(np.percentile(after, 90)), 3) if after else None,
            "decisions": len(after)}


def _delays(run: IdentityRun, frame_rate: float, after: Sequence[float]
            ) -> dict[str, float | None]:
    """Decision times of the segments after cuts, s: ``median``/``max`` of (decision frame
    - segment boundary); ``after_transition_median``: the median of ``after``
    (``decision_delays_after``)."""
    d = [(m.decided_frame - m.boundary) / frame_rate for m in run.tracker.history
         if not m.correction and m.segment > 0]
    out: dict[str, float | None] = {"median": None, "max": None, "after_transition_median": None}
    if d:
        out["median"] = round(float(np.median(d)), 3)
        out["max"] = round(float(np.max(d)), 3)
    if after:
        out["after_transition_median"] = round(float(np.median(after)), 3)
    return out


# --------------------------------------------------------------------------- CLI path
def format_identity_table(doc: dict[str, Any]) -> str:
    """The ``identity`` report as text: per take, per group and pooled."""
    lines = [f"behaviour identity (live, causal: the ids sent; {doc.get('primary', '')} cuts)",
             f"{'take':<16} {'ARI':>6} {'NMI':>6} {'ARI+c':>6}  {'segs':>4} {'ids':>4} "
             f"{'true':>4} {'corr':>4}  {'dec_s':>6} {'vs_lab':>6}"]
    for k, t in doc["takes"].items():
        d = t["decision_delay_s"]["median"]
        dl = t["decision_delay_s"]["after_transition_median"]
        lines.append(f"{k:<16} {t['ari']:6.3f} {t['nmi']:6.3f} {t['corrected']['ari']:6.3f}  "
                     f"{t['segments']:4d} {t['behaviours']:4d} {t['true_behaviours']:4d} "
                     f"{t['corrections']:4d}  {'-' if d is None else f'{d:.2f}':>6} "
                     f"{'-' if dl is None else f'{dl:.2f}':>6}")
    def vs_lab(s: dict) -> str:
        d = s.get("decision_delay_s", {}).get("after_transition_median")
        return f"{'-' if d is None else f'{d:.2f}':>6}"
    pad = " " * 35
    for g, s in doc["groups"].items():
        lines.append(f"{'pooled ' + g:<16} {s['ari']:6.3f} {s['nmi']:6.3f}{pad}{vs_lab(s)}")
    lines.append(f"{'pooled':<16} {doc['pooled']['ari']:6.3f} {doc['pooled']['nmi']:6.3f}"
                 f"{pad}{vs_lab(doc['pooled'])}")
    nm = doc.get("named")
    if nm:
        nl = nm["not_in_library"]
        dd = nm["decision_delay_s"]["after_transition_median"]
        lines.append(f"named by the library: {nm['segments']} segments of its behaviours: "
                     f"right {nm['accuracy']}, unknown {nm['unknown_rate']}, wrong "
                     f"{nm['wrong_rate']}; {nl['segments']} of other behaviours: unknown "
                     f"{nl['unknown_rate']}; name decided a median "
                     f"{'-' if dd is None else f'{dd:.2f}'} s after the change")
    lib = doc.get("library")
    if lib:
        lines.append(f"library (named, leave-one-take-out over {', '.join(lib['takes'])}): "
                     f"accuracy {lib['accuracy']}, unknown {lib['unknown_rate']} of "
                     f"{lib['known_segments']} segments; left out of the library, "
                     f"unknown {lib['unknown_correct']} of {lib['unknown_segments']}")
    lines.append("ARI+c: with the corrections applied; ids: per take (pooled over the takes' "
                 "frames concatenated); dec_s: median s from segment boundary to its id; "
                 "vs_lab: from the labelled transition")
    return "\n".join(lines) + "\n"


def run_evaluate_identity(args: Any) -> int:
    """``rtseg evaluate DATA --online --identity [--json]``: JSON ``{"live_default",
    "identity": {"pooled", "groups", "takes"}}`` or a table.  Takes: ``--group`` (default
    cmu and tsseg4d)."""
    import json
    import sys
    from rtseg.progress import Progress
    from rtseg.labels.takes import GROUPS, find_labelled_takes, no_takes_hint
    from rtseg.evaluation.online import live_config
    if not args.online:
        raise ValueError("--identity scores what the live loop sends: add --online")
    methods = None if args.method == "all" else [args.method]
    cfg, default = live_config(args.config, methods)
    cfg["identity.enabled"] = True
    groups = (("cmu", "tsseg4d") if args.group is None
              else GROUPS if args.group == "all" else (args.group,))
    takes = find_labelled_takes(args.data_dir, groups)
    if not takes:
        raise ValueError(f"no labelled takes of {', '.join(groups)} found in {args.data_dir}"
                         + no_takes_hint(args.data_dir))
    library = None
    if getattr(args, "behaviours", None):
        from rtseg.library.behaviours import load
        library = load(args.behaviours)
    bar = Progress(len(takes), enabled=not args.no_progress)
    doc = evaluate_identity(takes, cfg, bar, library)
    bar.close()
    if library is not None and len(doc["named"]["skipped_takes"]) == len(takes):
        raise ValueError(f"--behaviours {args.behaviours}: learned for feature profile "
                         f"{library.profile!r} ({library.dims} dims); none of the takes "
                         f"evaluated has those features")
    primary = cfg["detectors.primary"] or cfg["detectors.methods"][0]
    doc = {"primary": primary, "threshold": cfg["identity.threshold"],
           "decide_after_s": cfg["identity.decide_after_s"], **doc}
    lib = library_loto(takes, cfg)
    if lib is not None:
        doc["library"] = lib
    if args.json:
        sys.stdout.write(json.dumps({"live_default": default, "identity": doc}, indent=2,
                                    allow_nan=False) + "\n")
    else:
        sys.stdout.write(format_identity_table(doc))
    return 0
