"""Offline PCA segmentation (``segment_pca``): the two-sided contrast scan (``variant =
"scan"``, the default), the paper's forward pass (``"paper"``) and the verified passes
(``"verified"``).

The scan: at every ``scan_step_s`` the two-sided contrast of ``rtseg.detectors._scan`` with
the PCA window distance (``rtseg.detectors.pca_distance.WindowPCA.distance``), averaged over
the window lengths ``scan_windows_s``; the changes are its local maxima reaching
``min_contrast``, at least the mean window apart, each cut at its maximum.

Offline verification (``variant = "verified"``; not in the paper).  The online pass
(``rtseg.detectors.pca``) is run unchanged; then every cut c between its neighbours p and
q is checked two-sided with the same PCA model the detector uses: A = X[max(p, c-W):c],
B = X[c:min(q, c+W)], each fitted with its mean and its top-r directions (E_r > tau), and

    contrast(c) = min( err(B | A) / err(A | A),  err(A | B) / err(B | B) )

where err(Y | Z) is the mean per-frame projection error of Y's frames off Z's model (so
err(A | A) = e / n of A, the paper's Eq. 5 per frame).  A true behaviour change leaves each
side badly explained by the other's hyperplane in BOTH directions; a within-behaviour swing
of d (a forward jump, one arm circle) is explained by a model of a few seconds of the same
behaviour, in at least one direction.  The cut with the lowest contrast is removed while it
is below ``verify_ratio`` (its neighbours' windows then grow and are re-scored); a cut
leaving a segment shorter than ``min_segment_s`` scores 0 (removed first, the weaker
detector confidence first).  Before the check the forward pass and a pass over the
time-reversed frames are merged (``merge_passes``: the backward pass covers the forward
pass's blind 3 s after each cut, and a forward/backward pair is one change, placed at its
mean).  After it each cut is moved to the contrast maximum within +-l (``refine_cuts``).
"""

from __future__ import annotations

import logging
from typing import Any, Mapping, Sequence

import numpy as np

from rtseg.detectors._scan import local_maxima, on_grid, window_contrast
from rtseg.detectors.base import Cut
from rtseg.detectors.pca import PCADetector
from rtseg.detectors.pca_distance import WindowPCA, cross_error, pca_model

log = logging.getLogger(__name__)


def cut_contrast(X: np.ndarray, prev: int, c: int, nxt: int, W: int, tau: float,
                 min_len: int = 2) -> float:
    """Two-sided PCA contrast of a cut at frame c whose neighbouring cuts are prev < c < nxt
    (0 and len(X) at the take's ends); see the module docstring.  0.0 when either side is
    shorter than ``min_len`` frames."""
    A = X[max(prev, c - W):c]
    B = X[c:min(nxt, c + W)]
    if len(A) < max(min_len, 2) or len(B) < max(min_len, 2):
        return 0.0
    return min(cross_error(B, pca_model(A, tau)), cross_error(A, pca_model(B, tau)))


def verify_cuts(X: np.ndarray, cuts: Sequence[Cut], W: int, min_len: int, ratio: float,
                tau: float) -> list[Cut]:
    """The cuts left after removing, weakest first, those whose ``cut_contrast`` (windows of
    at most W frames, segments of at least ``min_len`` frames) is below ``ratio``.  Sorted
    by frame."""
    kept = sorted(cuts, key=lambda c: c.frame)
    n = len(X)
    cache: dict[tuple[int, int, int], float] = {}
    while kept:
        scores = []
        for i, c in enumerate(kept):
            prev = kept[i - 1].frame if i else 0
            nxt = kept[i + 1].frame if i + 1 < len(kept) else n
            key = (prev, c.frame, nxt)
            if key not in cache:
                cache[key] = cut_contrast(X, prev, c.frame, nxt, W, tau, min_len)
            scores.append(cache[key])
        j = min(range(len(kept)), key=lambda i: (scores[i], kept[i].confidence))
        if scores[j] >= ratio:
            break
        log.debug("pca: cut at frame %d dropped, contrast %.2f < %.2f",
                  kept[j].frame, scores[j], ratio)
        del kept[j]
    return kept


def refine_cuts(X: np.ndarray, cuts: Sequence[Cut], W: int, min_len: int, reach: int,
                tau: float) -> list[Cut]:
    """Each cut moved to the frame within +-``reach`` of it where ``cut_contrast`` (windows
    of at most W frames, bounded by the neighbouring cuts) is highest, in time order (the
    previous cut already moved).  Candidates every max(1, reach // 15) frames; a cut stays
    at least ``min_len`` frames from its neighbours.  The detector's cut frame is only known
    to within its lag (d sums the last l frames; forward and backward passes are late in
    opposite directions), while the two-sided contrast peaks where the two sides' PCA models
    differ most.  Moved cuts are batch cuts: ``detected_at == frame``."""
    cs = sorted(cuts, key=lambda c: c.frame)
    n = len(X)
    step = max(1, reach // 15)
    out: list[Cut] = []
    for i, c in enumerate(cs):
        prev = out[-1].frame if out else 0
        nxt = cs[i + 1].frame if i + 1 < len(cs) else n
        lo, hi = max(prev + min_len, c.frame - reach), min(nxt - min_len, c.frame + reach)
        best, best_k = c.frame, -1.0
        for f in range(lo, hi + 1, step):
            k = cut_contrast(X, prev, f, nxt, W, tau, 2)
            if k > best_k:
                best, best_k = f, k
        out.append(c if best == c.frame else
                   Cut(frame=best, method=c.method, confidence=c.confidence,
                       detected_at=best, score=c.score))
    return out


def contrast_profile(X: np.ndarray, windows: Sequence[int], step: int,
                     tau: float) -> tuple[np.ndarray, np.ndarray]:
    """The two-sided PCA contrast (``rtseg.detectors._scan``, D = ``WindowPCA.distance``)
    averaged over the window lengths ``windows`` (frames), at every ``step``-th frame c from
    min(windows) to n - min(windows)/2.  Averaging over a few window lengths keeps the
    maxima from depending on one length's fit to the take's behaviour durations.  A length
    W counts at c only where its window before c is whole (c >= W; a window cut short by
    the take's start has a narrower model, which alone inflates the contrast) and the one
    after c holds at least W/2 frames, and where it has a whole outer window; the mean is
    over the lengths that count there (near the take's ends, fewer).  Returns
    (frames, contrast); +inf where none counts (takes shorter than about 3 windows).
    Windows fall on the grid of ``step`` frames when their lengths are multiples of it, so
    each is fitted once."""
    X = np.asarray(X, dtype=np.float64)
    Ws = sorted({int(w) for w in windows})
    if not Ws or Ws[0] < 2:
        raise ValueError(f"scan windows must be >= 2 frames, got {list(windows)}")
    n = len(X)
    frames_ = np.arange(Ws[0], n - max(2, Ws[0] // 2) + 1, max(1, int(step)))
    cache = WindowPCA(X, tau)
    k = np.full((len(Ws), len(frames_)), np.inf)
    for i, W in enumerate(Ws):
        for j, c in enumerate(frames_):
            if W <= c <= n - max(2, W // 2):
                k[i, j] = window_contrast(cache.distance, n, int(c), W)
    finite = np.isfinite(k)
    count = finite.sum(axis=0)
    mean = np.where(finite, k, 0.0).sum(axis=0) / np.maximum(count, 1)
    return frames_, np.where(count > 0, mean, np.inf)


def scan_windows(p: Mapping[str, Any], frame_rate: float) -> tuple[list[int], int]:
    """(window lengths, step) of the offline scan in frames for parameters ``p``
    (``scan_windows_s``, ``scan_step_s``), the lengths rounded to whole steps."""
    from rtseg.detectors import frames
    step = frames(p["scan_step_s"], frame_rate)
    return [on_grid(frames(w, frame_rate), step) for w in p["scan_windows_s"]], step


def scan_cuts(X: np.ndarray, windows: Sequence[int], step: int, min_contrast: float,
              tau: float) -> list[tuple[int, float]] | None:
    """(frame, contrast) of the local maxima of ``contrast_profile`` reaching
    ``min_contrast``, at least the mean window apart, sorted by frame; None when the take is
    too short for any position to be checked."""
    frames_, k = contrast_profile(X, windows, step, tau)
    sep = int(round(float(np.mean([int(w) for w in windows]))))
    return local_maxima(frames_, k, min_contrast, sep)


def merge_passes(forward: Sequence[Cut], backward: Sequence[Cut], tol: int) -> list[Cut]:
    """One list from the cuts of a forward and a backward pass (frames in forward order).

    The forward pass cuts where d has risen (after the change), the backward pass where
    the reversed d has risen (before it): a forward and a backward cut within ``tol``
    frames of each other (closest pairs first) are one change, placed at their mean frame.
    Unpaired cuts are kept; then cuts closer than ``tol`` are merged into their mean.
    Merged cuts are batch cuts: ``detected_at == frame``, the higher confidence.
    """
    F = sorted(forward, key=lambda c: c.frame)
    B = sorted(backward, key=lambda c: c.frame)
    pairs = sorted((abs(f.frame - b.frame), i, j) for i, f in enumerate(F)
                   for j, b in enumerate(B) if abs(f.frame - b.frame) <= tol)
    used_f: set[int] = set()
    used_b: set[int] = set()
    out: list[Cut] = []
    for _, i, j in pairs:
        if i in used_f or j in used_b:
            continue
        used_f.add(i)
        used_b.add(j)
        out.append(_merged([F[i], B[j]]))
    out += [c for i, c in enumerate(F) if i not in used_f]
    out += [c for j, c in enumerate(B) if j not in used_b]
    out.sort(key=lambda c: c.frame)
    merged: list[Cut] = []
    group: list[Cut] = []
    for c in out:
        if group and c.frame - group[-1].frame >= tol:
            merged.append(_merged(group))
            group = []
        group.append(c)
    if group:
        merged.append(_merged(group))
    return merged


def _merged(group: Sequence[Cut]) -> Cut:
    if len(group) == 1:
        return group[0]
    frame = int(round(sum(c.frame for c in group) / len(group)))
    best = max(group, key=lambda c: c.confidence)
    return Cut(frame=frame, method=best.method, confidence=best.confidence,
               detected_at=frame, score=best.score)


def segment_pca(X: np.ndarray, p: Mapping[str, Any], frame_rate: float,
                keep_trace: bool = False) -> tuple[list[Cut], list]:
    """Offline PCA segmentation of a whole feature matrix X (frames, dims).

    ``variant = "paper"``: the online detector's forward pass over X, unchanged.
    ``variant = "scan"`` (default): the changes are the local maxima of the two-sided PCA
    contrast averaged over the window lengths ``scan_windows_s``, every ``scan_step_s``
    (``scan_cuts``), that reach ``min_contrast``, at least the mean window apart; each cut
    is at its maximum (``detected_at == frame``).  A take too short to scan (< 3 of the
    longest window) falls back to "verified".
    ``variant = "verified"``: the online detector run forward and on the time-reversed X
    (backward cuts mapped to forward frames: reversed frame j -> len(X) - j), the two merged
    (``merge_passes``, tolerance ``min_segment_s``), then ``verify_cuts`` (windows
    ``verify_window_s``, segments >= ``min_segment_s``, contrast >= ``verify_ratio``), then
    ``refine_cuts`` (each cut to the contrast maximum within +-``lag_s``).
    Returns (cuts sorted by frame, the forward pass's trace).
    """
    from rtseg.detectors import frames
    det = PCADetector.from_params(p, frame_rate, keep_trace=keep_trace)
    variant = p.get("variant", "paper")
    if variant == "scan":
        X = np.asarray(X, dtype=np.float64)
        windows, step = scan_windows(p, frame_rate)
        found = scan_cuts(X, windows, step, float(p["min_contrast"]), float(p["energy"]))
        if found is not None:
            if keep_trace:          # the forward pass's d and threshold, for plotting
                det.run(X)
            return [Cut(frame=f, method="pca", detected_at=f, score=k,
                        confidence=min(max(1.0 - float(p["min_contrast"]) / k, 0.0), 1.0))
                    for f, k in found], det.trace
        variant = "verified"      # too short to scan: check the passes' cuts instead
    cuts = det.run(X)
    if variant == "verified":
        n = len(X)
        back = PCADetector.from_params(p, frame_rate).run(X[::-1])
        back = [Cut(frame=n - c.frame, method=c.method, confidence=c.confidence,
                    detected_at=n - c.frame, score=c.score) for c in back]
        min_len = frames(p["min_segment_s"], frame_rate)
        cuts = merge_passes(cuts, [c for c in back if 0 < c.frame < n], min_len)
        W = frames(p["verify_window_s"], frame_rate)
        if cuts:
            cuts = verify_cuts(X, cuts, W=W, min_len=min_len, ratio=float(p["verify_ratio"]),
                               tau=float(p["energy"]))
            cuts = refine_cuts(X, cuts, W=W, min_len=min_len,
                               reach=frames(p["lag_s"], frame_rate), tau=float(p["energy"]))
    return sorted(cuts, key=lambda c: c.frame), det.trace
