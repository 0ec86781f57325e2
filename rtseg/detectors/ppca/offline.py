"""Offline PPCA segmentation (``segment_ppca``): the paper's alternating passes
(``variant = "paper"``), or (``"verified"``, the default; not in the paper) the two-sided
contrast scan with the PPCA window distance, each change placed by the paper's
forward/backward passes.

Why a scan: the forward/backward passes over-segment behaviours whose cycle is longer than
T (alternating-side exercises: toe touches, knee raises): H peaks when the model of one
side meets the other.  The scan compares, at every Delta, the paper's own symmetric
distance (Fig. 6: the larger of the two mean Mahalanobis distances between two windows,
each scored against the other's PPCA model; ``rtseg.detectors.ppca.distance``) between
the W = ``verify_window_s`` windows before and after c (3 s, longer than the cycles of
such exercises) with the same distance between consecutive W windows on either side
(c-2W..c-W vs c-W..c, c..c+W vs c+W..c+2W): a behaviour boundary is a larger change than
the within-behaviour drift next to it.  The changes are the contrast's local maxima
reaching ``min_contrast``, at least W apart (``scan_cuts``); each is placed at the mean of
the nearest forward and backward pass peak, blended with the contrast maximum by
``scan_weight`` (``localise_cuts``).  A take too short to scan keeps the passes' cuts that
pass the same check one by one (``verify_cuts``).

Frames count from 0 (rows of X); windows and steps are in frames here, in seconds in
``config/detectors.toml``.  The online detector (``rtseg.detectors.ppca.online.PPCADetector``) is
the paper's forward pass, unverified.
"""

from __future__ import annotations

import logging
from typing import Any, Mapping

import numpy as np

from rtseg.detectors._scan import local_maxima, on_grid
from rtseg.detectors.base import Cut
from rtseg.detectors.ppca.online import PPCADetector
from rtseg.detectors.ppca.distance import WindowPPCA, cut_contrast

log = logging.getLogger(__name__)


def verify_cuts(X: np.ndarray, cuts: list[Cut], W: int, min_contrast: float, tau: float,
                noise_floor: float = 1e-6, null_rel: float = 1e-15,
                distance: str = "mean") -> list[Cut]:
    """The cuts that pass the two-sided check, sorted by frame.

    A cut is kept when its ``cut_contrast`` (windows of W frames) is at least
    ``min_contrast`` and no stronger kept cut lies within W frames of it: cuts are accepted
    in decreasing contrast, and a weaker cut closer than W to an accepted one is dropped,
    because its windows straddle that stronger change and its test is not valid (this also
    merges double cuts around one transition).  Behaviours shorter than W are therefore
    not separated from their neighbours by this check.
    """
    scored = []
    for c in cuts:
        k = cut_contrast(X, c.frame, W, tau, noise_floor, null_rel, distance)
        if k >= min_contrast:
            scored.append((k, c))
        else:
            log.debug("ppca: cut at frame %d dropped, contrast %.2f < %.2f",
                      c.frame, k, min_contrast)
    kept: list[Cut] = []
    for k, c in sorted(scored, key=lambda kc: (-kc[0], kc[1].frame)):
        if all(abs(c.frame - o.frame) >= W for o in kept):
            kept.append(c)
        else:
            log.debug("ppca: cut at frame %d dropped, within %d frames of a stronger cut",
                      c.frame, W)
    return sorted(kept, key=lambda c: c.frame)


def contrast_profile(X: np.ndarray, W: int, step: int, tau: float, noise_floor: float = 1e-6,
                     null_rel: float = 1e-15,
                     distance: str = "mean") -> tuple[np.ndarray, np.ndarray]:
    """``cut_contrast`` at every ``step``-th frame c from W to n - W/2.

    The scan starts once a whole window precedes c (a window cut short by the start of the
    take has a narrower model, which alone inflates the contrast; the forward pass likewise
    tests nothing in its first T frames) and ends where the window after c would be shorter
    than W/2.  Returns (frames, contrast); +inf where the check is impossible (no outer
    window: takes shorter than 3 W).  Windows fall on the grid of ``step`` frames,
    so each W-frame window is fitted once: cost ~ (n / step) PPCA fits of W x d windows."""
    X = np.asarray(X, dtype=np.float64)
    h = max(2, W // 2)
    frames_ = np.arange(W, len(X) - h + 1, max(1, int(step)))
    models = WindowPPCA(X, tau, noise_floor, null_rel, distance)
    return frames_, np.array([models.contrast(int(c), W) for c in frames_], dtype=float)


def scan_window(p: Mapping[str, Any], frame_rate: float) -> tuple[int, int]:
    """(W, step) of the offline scan in frames for parameters ``p`` (``verify_window_s``,
    ``step_s`` = Delta), W rounded to whole steps."""
    from rtseg.detectors.base import frames
    step = frames(p["step_s"], frame_rate)
    return on_grid(frames(p["verify_window_s"], frame_rate), step), step


def scan_cuts(X: np.ndarray, W: int, step: int, min_contrast: float, tau: float,
              noise_floor: float = 1e-6, null_rel: float = 1e-15,
              distance: str = "mean") -> list[tuple[int, float]] | None:
    """(frame, contrast) of the local maxima of ``contrast_profile`` that reach
    ``min_contrast``, at least W frames apart (a higher maximum wins), sorted by frame.
    None when no position of the take can be checked (see ``contrast_profile``)."""
    frames_, k = contrast_profile(X, W, step, tau, noise_floor, null_rel, distance)
    return local_maxima(frames_, k, min_contrast, W)


def localise_cuts(X: np.ndarray, frames_: list[int], det_args: dict[str, Any],
                  reach: int, anchors: list[int] | None = None,
                  anchor_weight: float = 0.0) -> list[int]:
    """Each change placed at the mean of the nearest forward-pass and backward-pass peak,
    optionally blended with a second estimate of its position.

    For a change near frame c between its neighbours p and q (or the take's ends), the
    paper's forward pass over X[p:q] and its backward pass over the reversed X[p:q] each
    propose cuts; the forward peak marks where the new motion starts to differ from the
    old behaviour's model (the start of the transition), the backward peak where the old
    motion starts to differ from the new one's (its end), so their mean is the middle of
    the transition, where labels put it.  Only peaks within ``reach`` frames of c count; with
    one of the two, the passes' estimate is that peak; with neither, c stays (or moves to
    its anchor when ``anchor_weight`` > 0).

    ``anchors`` (one frame per change, e.g. the contrast maximum of ``scan_cuts``): the
    result is ``(1 - anchor_weight) * passes' estimate + anchor_weight * anchor``.  Two
    estimates with independent errors average to a smaller error than either.  One frame
    per input frame."""
    n = len(X)
    if anchors is not None and len(anchors) != len(frames_):
        raise ValueError(f"{len(anchors)} anchors for {len(frames_)} changes")
    if not 0.0 <= anchor_weight <= 1.0:
        raise ValueError(f"anchor_weight must be in [0, 1], got {anchor_weight}")
    w = float(anchor_weight) if anchors is not None else 0.0
    bounds = [0] + list(frames_) + [n]
    out = []
    for i, c in enumerate(frames_):
        lo, hi = bounds[i], bounds[i + 2]
        seg = X[lo:hi]
        fwd = [lo + k.frame for k in _pass(seg, det_args)]
        bwd = [hi - k.frame for k in _pass(seg[::-1], det_args)]
        near = [min(side, key=lambda f: abs(f - c)) for side in (fwd, bwd) if side]
        near = [f for f in near if abs(f - c) <= reach]
        est = float(np.mean(near)) if near else float(c)
        if w > 0.0:
            est = (1.0 - w) * est + w * anchors[i] if near else float(anchors[i])
        out.append(int(round(est)))
    return out


def _pass(X: np.ndarray, det_args: dict[str, Any]) -> list[Cut]:
    if len(X) < 2 * det_args["T"] + det_args["delta"]:
        return []
    return PPCADetector(**det_args).run(X)


def segment_ppca(X: np.ndarray, p: Mapping[str, Any], frame_rate: float,
                 keep_trace: bool = False) -> tuple[list[Cut], list]:
    """Offline PPCA.

    ``variant = "paper"`` (Barbič et al. 2004 as published): forward pass, then backward,
    forward, ... within the segments found so far, until a pass adds no cut (at most
    ``max_passes``).  Cuts of the first (forward) pass keep their online ``detected_at``;
    cuts added by later passes are batch results (``detected_at == frame``).

    ``variant = "verified"`` (default): the changes are the local maxima of the two-sided
    contrast (``scan_cuts``: ``cut_contrast`` with windows of ``verify_window_s`` every
    ``step_s``, kept when >= ``min_contrast``, at least one window apart), i.e. the frames
    where the motion before and after differ more than consecutive windows on either side
    do; each starts from the alternating passes' nearest cut within W/2 (if any) and is
    then placed by the paper's own passes (``localise_cuts``: the mean of the nearest
    forward and backward peak within T).  On a take too short for any contrast (< about
    3 windows) the alternating passes' cuts are checked with ``verify_cuts`` instead.
    ``detected_at == frame`` (batch).

    The trace is the first forward pass's (H and its threshold, for plotting).
    """
    from rtseg.detectors.base import frames
    args = dict(T=frames(p["window_s"], frame_rate), delta=frames(p["step_s"], frame_rate),
                tau=p["energy"], R=p["peak_threshold"], distance=p["distance"],
                noise_floor=p["noise_floor"], null_rel=p["null_rel"],
                reference_dims=p["reference_dims"])
    X = np.asarray(X, dtype=np.float64)
    n = len(X)
    first = PPCADetector(keep_trace=keep_trace, **args)
    cuts: dict[int, Cut] = {c.frame: c for c in first.run(X)}
    backward = True
    for _ in range(int(p["max_passes"]) - 1):
        bounds = [0] + sorted(cuts) + [n]
        new: list[Cut] = []
        for a, b in zip(bounds[:-1], bounds[1:]):
            seg = X[a:b][::-1] if backward else X[a:b]
            for c in _pass(seg, args):
                f = b - c.frame if backward else a + c.frame
                new.append(Cut(frame=f, method="ppca", confidence=c.confidence,
                               detected_at=f, score=c.score))
        if not new:
            break
        for c in new:
            cuts.setdefault(c.frame, c)
        backward = not backward
    out = sorted(cuts.values(), key=lambda c: c.frame)
    if p.get("variant", "verified") != "verified":
        return out, first.trace
    W = scan_window(p, frame_rate)[0]
    check = (args["tau"], args["noise_floor"], args["null_rel"], args["distance"])
    found = scan_cuts(X, W, args["delta"], float(p["min_contrast"]), *check)
    if found is None:   # too short to scan: check the passes' cuts where possible
        return verify_cuts(X, out, W, float(p["min_contrast"]), *check), first.trace
    # each change starts from the passes' nearest cut (a peak of H) within W/2, if any:
    # the contrast maximum only places it to within a fraction of its 3 s windows
    starts = []
    for f, _ in found:
        near = [c.frame for c in out if abs(c.frame - f) <= W // 2]
        starts.append(min(near, key=lambda g: abs(g - f)) if near else f)
    at = localise_cuts(X, starts, args, reach=args["T"], anchors=[f for f, _ in found],
                       anchor_weight=float(p.get("scan_weight", 0.0)))
    placed: dict[int, Cut] = {}
    for f, (_, k) in zip(at, found):
        if f not in placed or k > placed[f].score:
            placed[f] = Cut(frame=f, method="ppca", detected_at=f, score=k,
                            confidence=min(max(1.0 - float(p["min_contrast"]) / k, 0.0), 1.0))
    return sorted(placed.values(), key=lambda c: c.frame), first.trace
