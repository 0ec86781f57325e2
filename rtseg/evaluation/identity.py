"""Scoring live behaviour identities against human labels (``rtseg evaluate --online
--identity``).

Per take: the take goes frame by frame through the live ``Pipeline`` with its
``IdentityTracker`` (``rtseg.identity.tracker``), exactly as ``rtseg live`` runs it; the frame
labels are the ids the tracker *sent*: each segment's decided id from its boundary on
(``decided``, the headline figure), and with the corrections applied (``corrected``).
Nothing is relabelled after the fact.  They are compared with the human labels per frame
(``rtseg.labels.truth``).

Scores: adjusted Rand index and normalised mutual information (scikit-learn), per take and
pooled over takes (the takes' frames concatenated, each take's ids kept apart since ids
are per session); decision delays in seconds after each labelled transition.  The report
of ``rtseg evaluate --online --identity`` that uses them is ``rtseg.evaluation.report``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from rtseg.identity.tracker import IdentityTracker


@dataclass
class IdentityRun:
    """What the live loop sent on one take."""
    decided: np.ndarray        # per-frame ids (decisions only)
    corrected: np.ndarray      # per-frame ids with corrections applied
    tracker: IdentityTracker
    cut_frames: list[int]


def run_identity(take: Any, config: Any, library: Any = None,
                 posture: bool = True) -> IdentityRun:
    """Replay ``take`` through the live pipeline (as ``rtseg.evaluation.online.live_cuts``) with
    identity on; the ids sent per frame.  ``library``: a ``rtseg.library.behaviours.Library`` naming
    the segments (``tracker.history`` carries the names).  ``posture`` False: the session
    is not told the take's rest geometry, as an IMU suit whose geometry is unknown (names
    by the model distance alone)."""
    from rtseg.live.pipeline import Pipeline
    cfg = config
    if not cfg["identity.enabled"]:
        cfg = type(config)({k: dict(v) for k, v in config.values.items()}, config.origin,
                           dict(config.detector_params))
        cfg["identity.enabled"] = True
    n, fr = take.n_frames, float(take.frame_rate)
    from rtseg.core.posture import RestPose
    pipe = Pipeline(take.joint_names, take.parents, take.space, fr, cfg,
                    rest=RestPose.find(take) if posture else None)
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


