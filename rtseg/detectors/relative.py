"""A floor under a change's strength set by the stream's own recent changes.

A performance whose behaviours differ a lot (running, jumping, then standing) makes
contrasts of tens at its changes; the small drifts inside a quiet behaviour (weight
shifts, looking around) can still reach the detector's fixed threshold, two to six times
the motion before them, while being a small fraction of what a change of this stream looks
like.  ``RelativeFloor`` keeps the contrasts of the last ``count`` cuts sent and admits a
new maximum only when it reaches ``fraction`` x their median.  Where every change is
subtle, the median is low and the floor lies under the fixed threshold: it never makes a
cut easier, only a cut far weaker than the stream's recent changes harder.

Before ``warm`` cuts have been sent there is no floor.  The floor outlives the detector's
restarts (a gap in the stream is not a new performer).  Scores are the contrast detector's
``Cut.score`` (the full look's ratio, stated for ``reference_dims``).
"""

from __future__ import annotations

from collections import deque

import numpy as np

#: cuts sent whose contrasts set the floor (their median)
RELATIVE_COUNT = 10
#: no floor until this many cuts have been sent
RELATIVE_WARM = 3


class RelativeFloor:
    """``admits(score)``: is ``score`` at least ``fraction`` x the median of the last
    ``count`` scores passed to ``sent``?  ``fraction`` 0 = always."""

    def __init__(self, fraction: float, count: int = RELATIVE_COUNT,
                 warm: int = RELATIVE_WARM) -> None:
        if not (0.0 <= fraction < 1.0):
            raise ValueError(f"relative_floor must be in [0, 1), got {fraction}")
        if count < 1 or not 1 <= warm <= count:
            raise ValueError(f"count must be >= 1 and warm in [1, count], got {count}, {warm}")
        self.fraction = float(fraction)
        self.warm = int(warm)
        self._scores: deque[float] = deque(maxlen=int(count))
        #: maxima refused so far
        self.refused = 0

    @property
    def floor(self) -> float:
        """The contrast a maximum must reach now (0 before ``warm`` cuts were sent)."""
        if self.fraction == 0.0 or len(self._scores) < self.warm:
            return 0.0
        return self.fraction * float(np.median(self._scores))

    def admits(self, score: float) -> bool:
        """Whether a maximum of contrast ``score`` may become a cut (counts a refusal)."""
        if score >= self.floor:
            return True
        self.refused += 1
        return False

    def sent(self, score: float) -> None:
        """A cut of contrast ``score`` was sent."""
        self._scores.append(float(score))
