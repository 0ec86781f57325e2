"""Causal peak picking: turn a profile that arrives one value at a time into events, once.

``CausalPeaks.update(position, value, now)`` takes the profile's next value (``position``:
the frame the value belongs to; ``now``: the frame whose arrival made it known) and
returns a ``Peak`` when a maximum is confirmed.  A maximum is a *candidate* when its value
reaches ``threshold``, lies at least ``min_gap`` frames after the last event, and exceeds
every value of the preceding ``min_gap`` frames; a higher value replaces it.  It is
confirmed (sent, never withdrawn) as soon as the profile falls below ``drop`` x its value,
or ``hold`` frames of positions after it brought nothing higher — whichever comes first
(or when ``confirm`` is called: another rule vouches for it).  So ``hold`` bounds the extra
delay and ``drop`` ends it early on a clean peak.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class Peak:
    """A confirmed maximum: its position and value, and the frame that confirmed it."""
    position: int
    value: float
    confirmed_at: int


class CausalPeaks:
    """Streaming maxima of a profile (positions in frames, increasing)."""

    def __init__(self, threshold: float, hold: int, min_gap: int, drop: float = 0.5) -> None:
        if hold < 0 or min_gap < 0:
            raise ValueError(f"hold and min_gap must be >= 0 frames (got {hold}, {min_gap})")
        if not 0.0 <= drop < 1.0:
            raise ValueError(f"drop must be in [0, 1), got {drop}")
        self.threshold, self.hold, self.min_gap, self.drop = float(threshold), int(hold), \
            int(min_gap), float(drop)
        self.reset()

    def reset(self) -> None:
        """Forget the profile (after a gap): no candidate, no recent values, no last event."""
        self._recent: deque[tuple[int, float]] = deque()
        self._cand: tuple[int, float] | None = None
        self._last = None

    @property
    def candidate(self) -> int | None:
        """The position of the maximum waiting for confirmation, if any."""
        return None if self._cand is None else self._cand[0]

    def forget(self, position: int) -> None:
        """The event at ``position`` was withdrawn: it no longer holds the next one
        ``min_gap`` away (a later maximum must still exceed the values before it)."""
        if self._last == position:
            self._last = None

    @property
    def candidate_value(self) -> float | None:
        """The value of the maximum waiting for confirmation, if any."""
        return None if self._cand is None else self._cand[1]

    def confirm(self, now: int) -> Peak | None:
        """Confirm the waiting maximum now (another rule vouches for it, e.g.
        ``rtseg.detectors.confirm``); None when none waits."""
        cand = self._cand
        if cand is None:
            return None
        self._last = cand[0]
        self._cand = None
        return Peak(cand[0], cand[1], now)

    def taken(self, position: int) -> None:
        """Another rule sent an event at ``position`` (``CutSender.send_now``): a waiting
        maximum within ``min_gap`` of it is dropped, and it holds the next one ``min_gap``
        away as an event of this profile's would."""
        cand = self._cand
        if cand is not None and abs(cand[0] - position) < self.min_gap:
            self._cand = None
        if self._last is None or position > self._last:
            self._last = position

    def update(self, position: int, value: float, now: int) -> Peak | None:
        """Feed the value at ``position`` (known since frame ``now``); a Peak once confirmed."""
        out = None
        recent = self._recent
        while recent and recent[0][0] < position - self.min_gap:
            recent.popleft()
        cand = self._cand
        if cand is not None:
            if value > cand[1]:
                self._cand = (position, value)
            elif value < self.drop * cand[1] or position - cand[0] >= self.hold:
                out = Peak(cand[0], cand[1], now)
                self._last = cand[0]
                self._cand = None
        elif (value >= self.threshold
              and (self._last is None or position - self._last >= self.min_gap)
              and all(value > v for _, v in recent)):
            self._cand = (position, value)
        recent.append((position, value))
        return out
