"""Offline PCA segmentation (``segment_pca``): the two-sided contrast scan (``variant =
"scan"``, the default) or the paper's online forward pass run over the take (``"paper"``).

The scan: at every ``scan_step_s`` the two-sided contrast of ``rtseg.detectors._scan`` with
the PCA window distance (``rtseg.detectors.pca.distance.WindowPCA.distance``), averaged over
the window lengths ``scan_windows_s``; the changes are its local maxima reaching
``min_contrast``, at least the mean window apart, each cut at its maximum
(``detected_at == frame``: a batch result).  Frames count from 0 (rows of X); window
lengths and the step are in frames here, in seconds in ``config/detectors.toml``.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from rtseg.detectors._scan import local_maxima, on_grid, window_contrast
from rtseg.detectors.base import Cut
from rtseg.detectors.pca.online import PCADetector
from rtseg.detectors.pca.distance import WindowPCA


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
    (frames, contrast); +inf where none counts (takes shorter than 2.5 windows).
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
    from rtseg.detectors.base import frames
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


def segment_pca(X: np.ndarray, p: Mapping[str, Any], frame_rate: float,
                keep_trace: bool = False) -> tuple[list[Cut], list]:
    """Offline PCA segmentation of a whole feature matrix X (frames, dims).

    ``variant = "paper"``: the online detector's forward pass over X, unchanged.
    ``variant = "scan"`` (default): the changes are the local maxima of the two-sided PCA
    contrast averaged over the window lengths ``scan_windows_s``, every ``scan_step_s``
    (``scan_cuts``), that reach ``min_contrast``, at least the mean window apart; each cut
    is at its maximum (``detected_at == frame``).  A take too short to scan (no position
    with a whole window before it and a whole outer window on one side, for any length:
    under 2.5 of the shortest window, 6.25 s with the defaults) gets the paper's forward
    pass instead, whose cuts are online cuts (``detected_at`` as the detector gave it).
    Returns (cuts sorted by frame, the forward pass's trace).
    """
    det = PCADetector.from_params(p, frame_rate, keep_trace=keep_trace)
    if p.get("variant", "paper") == "scan":
        X = np.asarray(X, dtype=np.float64)
        windows, step = scan_windows(p, frame_rate)
        found = scan_cuts(X, windows, step, float(p["min_contrast"]), float(p["energy"]))
        if found is not None:
            if keep_trace:          # the forward pass's d and threshold, for plotting
                det.run(X)
            return [Cut(frame=f, method="pca", detected_at=f, score=k,
                        confidence=min(max(1.0 - float(p["min_contrast"]) / k, 0.0), 1.0))
                    for f, k in found], det.trace
        # too short to scan: the paper's forward pass below
    return sorted(det.run(X), key=lambda c: c.frame), det.trace
