"""Scoring live behaviour identities against human labels (``rtseg evaluate --online
--identity``).

Per take: the take goes frame by frame through the live ``Pipeline`` with its
``IdentityTracker`` (``rtseg.identity``), exactly as ``rtseg live`` runs it; the frame
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
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from rtseg.identity import IdentityTracker, tracker_from_config
from rtseg.labels import MOCAP6_BLOCK, LabelledTake, read_frame_label_column, _int_tokens


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


def run_identity(take: Any, config: Any) -> IdentityRun:
    """Replay ``take`` through the live pipeline (as ``rtseg.online_eval.live_cuts``) with
    identity on; the ids sent per frame."""
    from rtseg.pipeline import Pipeline
    cfg = config
    if not cfg["identity.enabled"]:
        cfg = type(config)({k: dict(v) for k, v in config.values.items()}, config.origin,
                           dict(config.detector_params))
        cfg["identity.enabled"] = True
    n, fr = take.n_frames, float(take.frame_rate)
    pipe = Pipeline(take.joint_names, take.parents, take.space, fr, cfg)
    tracker = pipe.identity
    valid = take.valid if take.valid is not None else np.ones((n, take.n_joints), dtype=bool)
    cuts: list[int] = []
    for i in range(n):
        for c in pipe.process(i, take.quats[i], valid[i], i, i / fr, 0, i / fr):
            if c.cut.method == tracker.method:
                cuts.append(int(c.boundary))
    return IdentityRun(tracker.frame_labels(n), tracker.frame_labels(n, corrected=True),
                       tracker, cuts)


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


def evaluate_identity(takes: Sequence[LabelledTake], config: Any,
                      progress: Any = None) -> dict[str, Any]:
    """``{"pooled": {ari, nmi}, "groups": {group: {ari, nmi}}, "takes": {name: {...}}}``
    for the causal identities the live loop sends on each take (see module docstring).
    Take keys are ``group/name`` when a name occurs in two groups."""
    names = [t.name for t in takes]
    per: dict[str, Any] = {}
    pairs: dict[str, list] = {}
    for lt in takes:
        key = lt.name if names.count(lt.name) == 1 else f"{lt.group}/{lt.name}"
        if progress is not None:
            progress.step(f"identity {key}")
        take = lt.load()
        run = run_identity(take, config)
        truth = truth_labels(lt, take.n_frames)
        st = run.tracker.stats
        per[key] = {"group": lt.group, **scores(truth, run.decided),
                    "corrected": scores(truth, run.corrected),
                    "segments": st.segments, "behaviours": st.new_behaviours,
                    "corrections": st.corrections, "true_behaviours": len(set(truth)),
                    "decision_delay_s": _delays(run, take.frame_rate)}
        pairs.setdefault(lt.group, []).append((key, truth, run.decided))
    allp = [p for g in pairs.values() for p in g]
    return {"pooled": pooled_scores(allp),
            "groups": {g: pooled_scores(v) for g, v in pairs.items()},
            "takes": per}


def _delays(run: IdentityRun, frame_rate: float) -> dict[str, float | None]:
    """Median and max of (decision frame - segment boundary) / frame rate, s (cuts only)."""
    d = [(m.decided_frame - m.boundary) / frame_rate for m in run.tracker.history
         if not m.correction and m.segment > 0]
    if not d:
        return {"median": None, "max": None}
    return {"median": round(float(np.median(d)), 3), "max": round(float(np.max(d)), 3)}
