"""Cuts from two looks at one contrast: a full look and an early one that must agree with it.

The contrast detector (``rtseg.detectors.contrast``) scores every grid position c twice:

- the **full look**, the two-window contrast with the whole after window (2 s at the
  defaults), known ``after`` frames after c;
- the **early look**, a one-sided contrast with a shorter after window (``early_after``,
  1 s), known sooner.  Alone it is noisy: a short window over a slow cycle differs from the
  3 s before it without any change of behaviour.

``EarlyCuts`` picks causal maxima (``CausalPeaks``) on each profile separately and merges
them into one stream of cuts:

- a full-look maximum is a cut, as it always was;
- an early-look maximum (at least ``early_threshold``) is a cut only when the full look
  *corroborates* it: some full-look value at most ``back`` frames before its position (at
  or after it too), known by the time the early maximum is confirmed, has reached
  ``backing`` x the full ``threshold``.  One that is not corroborated then is dropped (the
  full look may still find the change later).  The full look at a position up to
  ``after`` frames before a change already sees part of it, and one more than ``back``
  before it sees the change before; a backing above 1 asks the full look for more than a
  cut of its own would;
- every cut lies at least ``min_gap`` frames from every cut already sent, whichever look
  sent it, so one change is sent once.

A cut found by the early look arrives up to ``after - early_after`` frames sooner.  The
two pickers are independent (each keeps its own last maximum); only the sending is merged.
Frame numbers are the caller's (positions and ``now``: the frame whose arrival made a value
known); nothing here depends on the frame rate.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from rtseg.detectors.peaks import CausalPeaks, Peak


@dataclass(frozen=True)
class EarlyCut:
    """A cut to send: the peak (position, value, confirming frame), which look found it,
    and its strength on the full look's scale: the full look's own maximum, or for an
    early maximum the highest full-look value that backed it (the early look's one-sided
    ratio runs to hundreds where the full look's reaches tens, so only this value compares
    across cuts); for a change ``send_now`` sent, the value it was sent with (the pre-look's:
    the same two-window ratio on a shorter after window)."""
    peak: Peak
    early: bool
    strength: float


class EarlyCuts:
    """Merge the full and early contrast profiles into cuts (module docstring).

    ``threshold``, ``hold``, ``drop``: the full look's peak picker; ``early_threshold``,
    ``early_hold``: the early look's (same ``drop``); ``early_after``: the early look's after
    window (frames); ``back``: how far before an early maximum the corroborating full-look
    values may lie (frames; None: ``early_after``); ``backing``: the factor of ``threshold``
    they must reach; ``min_gap``: frames between any two cuts.  ``early_threshold`` None
    turns the early look off.
    """

    def __init__(self, threshold: float, hold: int, min_gap: int, drop: float,
                 early_threshold: float | None, early_hold: int, early_after: int,
                 back: int | None = None, backing: float = 1.0) -> None:
        self.threshold = float(threshold)
        self.min_gap = int(min_gap)
        self.back = int(early_after) if back is None else min(int(back), int(early_after))
        if not backing > 0:
            raise ValueError(f"backing must be positive, got {backing}")
        self.backing = float(backing)
        # full-look values kept: those an early maximum (at most early_hold behind the
        # early look, which runs ahead of the full one) may still need
        self._keep = int(early_after) + int(early_hold) + int(min_gap)
        self.full = CausalPeaks(threshold, hold=hold, min_gap=min_gap, drop=drop)
        self.early = (CausalPeaks(early_threshold, hold=early_hold, min_gap=min_gap, drop=drop)
                      if early_threshold is not None else None)
        self.reset()

    @property
    def candidate(self) -> int | None:
        """The position of the full look's maximum waiting for confirmation, else the
        early look's, else None."""
        pos = self.full.candidate
        if pos is None and self.early is not None:
            pos = self.early.candidate
        return pos

    def reset(self) -> None:
        """Forget both profiles and the cuts sent (after a gap)."""
        self.full.reset()
        if self.early is not None:
            self.early.reset()
        self._full_recent: deque[tuple[int, float]] = deque()   # (position, full value)
        self._sent: deque[int] = deque()                        # positions of sent cuts

    def update_full(self, position: int, value: float, now: int) -> EarlyCut | None:
        """The full look's value at ``position``, known since frame ``now``."""
        if self.early is not None:
            recent = self._full_recent
            recent.append((position, value))
            while recent and recent[0][0] < position - self._keep:
                recent.popleft()
        peak = self.full.update(position, value, now)
        return self._send(peak, False, peak.value) if peak is not None else None

    def confirm_full(self, now: int) -> EarlyCut | None:
        """Send the full look's waiting maximum now (``rtseg.detectors.confirm`` vouches
        for it); None when none waits or a cut lies within ``min_gap`` of it."""
        peak = self.full.confirm(now)
        return self._send(peak, False, peak.value) if peak is not None else None

    def send_now(self, position: int, value: float, now: int) -> EarlyCut | None:
        """Send a change another look vouches for (``rtseg.detectors.prelook``) at
        ``position`` with ``value`` as its strength, found on frame ``now``; None when a cut
        lies within ``min_gap`` of it.  The full look's waiting maximum near it is dropped
        and its next one kept ``min_gap`` away."""
        sent = self._send(Peak(position, value, now), True, value)
        if sent is not None:
            self.full.taken(position)
        return sent

    def update_early(self, position: int, value: float, now: int) -> EarlyCut | None:
        """The early look's value at ``position``, known since frame ``now``."""
        if self.early is None:
            return None
        peak = self.early.update(position, value, now)
        if peak is None:
            return None
        since = peak.position - self.back
        backing = max((v for p, v in self._full_recent if p >= since), default=-math.inf)
        if not backing >= self.backing * self.threshold:
            return None
        return self._send(peak, True, backing)

    def forget(self, position: int) -> None:
        """A cut sent at ``position`` was withdrawn before it went out (the same-behaviour
        gate dropped it): it no longer keeps other cuts ``min_gap`` away, and the look
        that found it may find a maximum again (one that exceeds the values before it)."""
        if position in self._sent:
            self._sent.remove(position)
        for look in (self.full, self.early):
            if look is not None:
                look.forget(position)

    def _send(self, peak: Peak, early: bool, strength: float) -> EarlyCut | None:
        sent = self._sent
        if any(abs(peak.position - p) < self.min_gap for p in sent):
            return None
        sent.append(peak.position)
        # cuts are >= min_gap apart, so at most 3 lie within min_gap of any position, and a
        # new peak lies near the newest ones (within the longest delay): 4 are enough
        while len(sent) > 4:
            sent.popleft()
        return EarlyCut(peak, early, float(strength))
