"""A floor under the window models' own residuals, set by the stream's own recent windows.

The contrast detector (``rtseg.detectors.contrast``) compares two windows by the projection
error of each one's frames off the other's PCA hyperplane, over that model's *own* error
(the mean per-frame error of its own frames off its own hyperplane).  A near-still window
(standing, a held pose, a slow drift) fits its own hyperplane almost exactly, so its own
error is close to the sensors' noise and any window's error over it becomes a large ratio:
one such window then dominates every distance it takes part in, in the contrast's
numerator or its denominator.  ``ResidualFloor`` keeps the own errors of the before
windows of the last ``count`` looks and every own error in a ratio is taken as at least
``fraction`` x their median (``window_models.pca_error``'s ``floor``): errors over a model
whose residual is far below what this stream's windows usually leave are stated over that
floor instead; models of ordinary motion are unchanged.  The floor is in the stream's own
units and follows it (another performer, suit or feature set): the detector's cuts do not
change when every feature is scaled.  It outlives the detector's restarts (a gap in the
stream is not a new performer).

``fraction`` 0.25 is the shipped ``[contrast] residual_floor``, chosen leave-one-person-out
over the 15 people of ../shared/data with the thresholds (``benchmarks/lopo.py``,
docs/live_detector.md); ``count`` 400 looks is 50 s at the 0.125 s step (200 or 800 give
the same scores there).  ``fraction`` 0 = no floor.
"""

from __future__ import annotations

import math
from bisect import bisect_left, insort
from collections import deque

#: looks whose before windows' own errors set the floor (their median)
RESIDUAL_LOOKS = 400


class ResidualFloor:
    """The running median of the last ``count`` own errors pushed, times ``fraction``
    (module docstring).  Each ``push`` costs a sorted insert and removal (no sort)."""

    def __init__(self, fraction: float, count: int = RESIDUAL_LOOKS) -> None:
        if not 0.0 <= fraction < 1.0:
            raise ValueError(f"residual_floor must be in [0, 1), got {fraction}")
        if count < 1:
            raise ValueError(f"count must be >= 1, got {count}")
        self.fraction = float(fraction)
        self.count = int(count)
        self._order: deque[float] = deque()     # in arrival order
        self._sorted: list[float] = []          # the same values, ascending
        #: the floor: ``fraction`` x the median of the values kept (0 before any)
        self.value = 0.0

    def push(self, own: float) -> float:
        """Keep ``own`` (a before window's own error; non-finite ones are ignored); the
        floor now in force."""
        if self.fraction == 0.0 or not math.isfinite(own):
            return self.value
        order, srt = self._order, self._sorted
        if len(order) == self.count:
            old = order.popleft()
            del srt[bisect_left(srt, old)]
        order.append(own)
        insort(srt, own)
        n = len(srt)
        mid = n // 2
        median = srt[mid] if n % 2 else 0.5 * (srt[mid - 1] + srt[mid])
        self.value = self.fraction * median
        return self.value
