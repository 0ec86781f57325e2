"""Two-sided contrast scans shared by the offline PCA and PPCA detectors.

A scan evaluates, at every ``step``-th frame c, how much more the motion changes at c than
just before and just after it, with windows of W frames:

    A0 = [c-2W, c-W)   A = [c-W, c)   B = [c, c+W)   B2 = [c+W, c+2W)
    contrast(c) = D(A, B) / mean(D(A0, A), D(B, B2))

for a method's own distance D between two windows (PPCA: the paper's symmetric Mahalanobis
distance of Fig. 6; PCA: the projection error of one window off the other's hyperplane).
A behaviour change makes D(A, B) larger than the change between consecutive windows of the
same behaviour (contrast > 1); inside a behaviour whose cycle is shorter than W it stays
about 1.  The changes are the local maxima of the contrast above a threshold, at least one
window apart.  Windows are (lo, hi) frame ranges, hi exclusive; frames count from 0.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

Window = tuple[int, int]


def on_grid(W: int, step: int) -> int:
    """W rounded to the nearest multiple of ``step`` (at least one step): windows on the
    scan's grid recur from position to position and are fitted once (e.g. 3 s at 100 Hz
    with a step of 8 frames: 300 -> 304 frames; about 2x faster)."""
    step = max(1, int(step))
    return step * max(1, int(round(W / step)))


def window_contrast(distance: Callable[[Window, Window], float], n: int, c: int,
                    W: int) -> float:
    """contrast(c) for a take of n frames (see the module docstring).

    A and B are cut short by the take's ends; an outer window (A0, B2) is used only when it
    is a whole W frames, and when neither is the contrast is +inf (cannot be checked).  A
    shorter outer window has a noisier, narrower model, and the profile jumps where it
    enters: with the outer windows allowed down to W/2, PPCA's maximum for a change 5 s into
    the synthetic takes sat at the last one-sided position, 70 frames early (synthetic F1
    0.95 against 1.00; cmu and tsseg4d unchanged).  +inf too when A or B has fewer than 2
    frames."""
    A, B = (max(0, c - W), c), (c, min(n, c + W))
    if A[1] - A[0] < 2 or B[1] - B[0] < 2:
        return math.inf
    cross = distance(A, B)
    A0, B2 = (max(0, c - 2 * W), max(0, c - W)), (min(n, c + W), min(n, c + 2 * W))
    need = max(2, W)
    inner = [distance(A0, A)] if A0[1] - A0[0] >= need else []
    if B2[1] - B2[0] >= need:
        inner.append(distance(B, B2))
    if not inner:
        return math.inf
    return cross / max(float(np.mean(inner)), 1e-300)


def local_maxima(frames_: np.ndarray, k: np.ndarray, min_contrast: float,
                 sep: int) -> list[tuple[int, float]] | None:
    """(frame, contrast) of the interior local maxima of the profile ``k`` sampled at
    ``frames_`` (evenly spaced) that reach ``min_contrast``, at least ``sep`` frames apart
    (a higher maximum wins; ties to the earlier), sorted by frame.  The first sample of a
    flat top counts; a rise still going at either end of the profile is not a maximum.
    None when no sample is finite (nothing could be checked)."""
    k = np.asarray(k, dtype=float)
    finite = np.isfinite(k)
    if not finite.any():
        return None
    k = np.where(finite, k, 0.0)
    i = np.arange(1, len(k) - 1)
    i = i[(k[i] > k[i - 1]) & (k[i] >= k[i + 1]) & (k[i] >= min_contrast)]
    step = int(frames_[1] - frames_[0]) if len(frames_) > 1 else 1
    gap = max(1, int(math.ceil(sep / max(1, step))))
    peaks: list[int] = []
    for j in sorted(i.tolist(), key=lambda j: (-k[j], j)):     # highest first
        if all(abs(j - q) >= gap for q in peaks):
            peaks.append(j)
    peaks.sort()
    return [(int(frames_[j]), float(k[j])) for j in peaks]
