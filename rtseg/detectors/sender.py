"""Which of the contrast detector's changes go out, and once each.

The contrast detector (``rtseg.detectors.contrast``) finds a change three ways:

- the **full look**'s causal maxima (``CausalPeaks``): sent once the profile falls below
  ``drop`` x the maximum or ``hold`` frames of positions after it brought nothing higher;
- the **short-look confirmation** (``rtseg.detectors.confirm``) vouching for the full look's
  waiting maximum sooner (``confirm_full``);
- the **pre-look** (``rtseg.detectors.prelook``) sending a strong change from a shorter
  after window before the full look has seen it (``send_now``).

``CutSender`` merges them into one stream: every change lies at least ``min_gap`` frames
from every change already sent, whichever way found it, so one change is sent once; a
change the pre-look sent drops the full look's waiting maximum near it.  Frame numbers are
the caller's (positions and ``now``: the frame whose arrival made a value known); nothing
here depends on the frame rate.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from rtseg.detectors.peaks import CausalPeaks, Peak


@dataclass(frozen=True)
class SentPeak:
    """A change to send: the peak (position, value, confirming frame), whether the
    pre-look sent it, and its strength: the full look's maximum, or the pre-look's value
    (the same two-window ratio on a shorter after window)."""
    peak: Peak
    prelook: bool
    strength: float


class CutSender:
    """The full look's peak picker (``threshold``, ``hold``, ``drop``) and the changes sent
    by any rule, ``min_gap`` frames apart (module docstring)."""

    def __init__(self, threshold: float, hold: int, min_gap: int, drop: float) -> None:
        self.min_gap = int(min_gap)
        self.full = CausalPeaks(threshold, hold=hold, min_gap=min_gap, drop=drop)
        self.reset()

    @property
    def candidate(self) -> int | None:
        """The position of the full look's maximum waiting for confirmation, or None."""
        return self.full.candidate

    def reset(self) -> None:
        """Forget the profile and the changes sent (after a gap)."""
        self.full.reset()
        self._sent: deque[int] = deque()                        # positions of sent cuts

    def update_full(self, position: int, value: float, now: int) -> SentPeak | None:
        """The full look's value at ``position``, known since frame ``now``."""
        peak = self.full.update(position, value, now)
        return self._send(peak, False, peak.value) if peak is not None else None

    def confirm_full(self, now: int) -> SentPeak | None:
        """Send the full look's waiting maximum now (``rtseg.detectors.confirm`` vouches
        for it); None when none waits or a cut lies within ``min_gap`` of it."""
        peak = self.full.confirm(now)
        return self._send(peak, False, peak.value) if peak is not None else None

    def send_now(self, position: int, value: float, now: int) -> SentPeak | None:
        """Send a change the pre-look (``rtseg.detectors.prelook``) vouches for at
        ``position`` with ``value`` as its strength, found on frame ``now``; None when a cut
        lies within ``min_gap`` of it.  The full look's waiting maximum near it is dropped
        and its next one kept ``min_gap`` away."""
        sent = self._send(Peak(position, value, now), True, value)
        if sent is not None:
            self.full.taken(position)
        return sent

    def forget(self, position: int) -> None:
        """A cut sent at ``position`` was withdrawn before it went out (the same-behaviour
        gate or the relative floor dropped it): it no longer keeps other cuts ``min_gap``
        away, and the full look may find a maximum again (one that exceeds the values
        before it)."""
        if position in self._sent:
            self._sent.remove(position)
        self.full.forget(position)

    def _send(self, peak: Peak, prelook: bool, strength: float) -> SentPeak | None:
        sent = self._sent
        if any(abs(peak.position - p) < self.min_gap for p in sent):
            return None
        sent.append(peak.position)
        # cuts are >= min_gap apart, so at most 3 lie within min_gap of any position, and a
        # new peak lies near the newest ones (within the longest delay): 4 are enough
        while len(sent) > 4:
            sent.popleft()
        return SentPeak(peak, prelook, float(strength))
