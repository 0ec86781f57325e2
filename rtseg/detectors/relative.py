"""A floor under a change's strength set by the stream's own recent changes.

A performance whose behaviours differ a lot (running, jumping, then standing) makes
contrasts of tens at its changes; the small drifts inside a quiet behaviour (weight
shifts, looking around) can still reach the detector's fixed threshold, two to six times
the motion before them, while being a small fraction of what a change of this stream looks
like.  ``RelativeFloor`` keeps the contrasts of the last ``count`` cuts sent and admits a
new maximum only when it reaches ``fraction`` x their median, or when the motion's energy
changes at it: the after window's mean variance per frame lies at least ``ENERGY_CHANGE``
times above the highest of the before windows' since the last cut (their last
``ENERGY_SPAN`` window lengths), or as far below the lowest.  A quiet behaviour's drift
stays within the energies that behaviour has shown (looking around comes and goes); a
change out of it into a vigorous one (idle -> punch, weak as a contrast because the quiet
windows already differ among themselves) does not.  Where every change is subtle, the
median is low and the floor lies under the fixed threshold: the floor never makes a cut
easier, only a cut far weaker than the stream's recent changes, at an unchanged energy,
harder.

Before ``warm`` cuts have been sent there is no floor.  The floor outlives the detector's
restarts (a gap in the stream is not a new performer).  Scores are the contrast detector's
``Cut.score`` (the full look's ratio, stated for ``reference_dims``).
"""

from __future__ import annotations

import logging
import math
from collections import deque

import numpy as np

log = logging.getLogger("rtseg.detectors")

#: cuts sent whose contrasts set the floor (their median)
RELATIVE_COUNT = 10
#: no floor until this many cuts have been sent
RELATIVE_WARM = 3
#: a maximum where the after window's energy (mean variance per frame) lies this many times
#: above the highest energy of the before windows since the last cut, or below the lowest
#: by as much, is admitted whatever its contrast
ENERGY_CHANGE = 2.0
#: ... of the last this many before windows' lengths at most
ENERGY_SPAN = 8


class RelativeFloor:
    """``admits(score, energy)``: is ``score`` at least ``fraction`` x the median of the
    last ``count`` scores passed to ``sent``, or ``energy`` (the after window's energy over
    the nearest end of the recent before windows' range, 1.0 within it) a change of at
    least ``ENERGY_CHANGE`` either way?  ``fraction`` 0 = always."""

    def __init__(self, fraction: float, count: int = RELATIVE_COUNT,
                 warm: int = RELATIVE_WARM) -> None:
        if not (0.0 <= fraction < 1.0):
            raise ValueError(f"relative_floor must be in [0, 1), got {fraction}")
        if count < 1 or not 1 <= warm <= count:
            raise ValueError(f"count must be >= 1 and warm in [1, count], got {count}, {warm}")
        self.fraction = float(fraction)
        self.warm = int(warm)
        self._scores: deque[float] = deque(maxlen=int(count))
        #: (frame, score, floor) of every maximum refused, for plots and benchmarks
        self.refusals: list[tuple[int, float, float]] = []

    @property
    def refused(self) -> int:
        """Maxima refused so far."""
        return len(self.refusals)

    @property
    def floor(self) -> float:
        """The contrast a maximum must reach now (0 before ``warm`` cuts were sent)."""
        if self.fraction == 0.0 or len(self._scores) < self.warm:
            return 0.0
        return self.fraction * float(np.median(self._scores))

    def admits(self, score: float, energy: float = 1.0, frame: int = -1) -> bool:
        """Whether a maximum of contrast ``score`` at ``frame`` may become a cut, ``energy``
        its energy change (class docstring; a refusal is counted and logged)."""
        floor = self.floor
        if score >= floor or not 1.0 / ENERGY_CHANGE < energy < ENERGY_CHANGE:
            return True
        self.refusals.append((int(frame), float(score), floor))
        log.info("contrast maximum at frame %d dropped: %.2f is below %.2f (%.2f x the median "
                 "of the last cuts), energy change %.2f (%d dropped so far)", frame,
                 score, floor, self.fraction, energy, self.refused)
        return False

    def sent(self, score: float) -> None:
        """A cut of contrast ``score`` was sent."""
        self._scores.append(float(score))


class EnergyRange:
    """The lowest and highest of the last ``span`` energies pushed (one per grid position,
    positions increasing), those at positions before a cut-off left out for good
    (``drop_before``): two monotone queues, so each push costs O(1) amortised instead of a
    scan of the span."""

    def __init__(self, span: int) -> None:
        if span < 1:
            raise ValueError(f"span must be >= 1, got {span}")
        self.span = int(span)
        self._n = 0                                        # values pushed so far
        self._low: deque[tuple[int, int, float]] = deque()   # (seq, position, energy)
        self._high: deque[tuple[int, int, float]] = deque()

    def drop_before(self, position: int) -> None:
        """Forget every value pushed at a position before ``position``."""
        for q in (self._low, self._high):
            while q and q[0][1] < position:
                q.popleft()

    def range_with(self, energy: float) -> tuple[float, float]:
        """(lowest, highest) of the remembered values and ``energy``."""
        lo = hi = energy
        if self._low and self._low[0][2] < lo:
            lo = self._low[0][2]
        if self._high and self._high[0][2] > hi:
            hi = self._high[0][2]
        return lo, hi

    def push(self, position: int, energy: float) -> None:
        """Remember ``energy`` at ``position`` (after every earlier position's)."""
        item = (self._n, position, energy)
        self._n += 1
        low, high = self._low, self._high
        while low and low[-1][2] >= energy:
            low.pop()
        low.append(item)
        while high and high[-1][2] <= energy:
            high.pop()
        high.append(item)
        oldest = self._n - self.span                     # the last span values stay
        for q in (low, high):
            while q[0][0] < oldest:
                q.popleft()


class EnergyChanges:
    """The energy change at each grid position the detector looks at: how far the after
    window's energy (mean variance per frame) lies outside the range of the before
    windows' energies since the last cut (``look``), and the newest ``keep`` of them by
    position (``at``: a maximum is sent at most ``hold`` after its look)."""

    def __init__(self, span: int, keep: int) -> None:
        #: the before windows' energies: the last ``span`` positions since the last cut
        self.before = EnergyRange(span)
        self._changes: deque[tuple[int, float]] = deque(maxlen=int(keep))

    def look(self, c: int, ea: float, eb: float, cut_off: int | None = None) -> float:
        """Position c's before window energy ``ea`` and after window energy ``eb``; the
        before windows of positions before ``cut_off`` (those that straddle the last cut
        sent) are left out for good first.  Returns eb / the highest energy above the
        range (``ea`` included), eb / the lowest below it, 1.0 within it."""
        rng = self.before
        if cut_off is not None:
            rng.drop_before(cut_off)
        lo, hi = rng.range_with(ea)
        rng.push(c, ea)
        if eb > hi:
            change = eb / hi if hi > 0 else math.inf
        else:
            change = eb / lo if eb < lo else 1.0
        self._changes.append((c, change))
        return change

    def at(self, c: int) -> float:
        """The energy change of the look at position c (1.0 when no longer remembered)."""
        for position, change in reversed(self._changes):
            if position == c:
                return change
        return 1.0
