"""The pre-look: a strong change of the contrast detector (``rtseg.detectors.contrast``) sent
from a shorter after window than the full look's, when the profile around it on that length
says it is the maximum.

The full look scores position c with the after window B = [c, c + after) and can send it no
sooner than ``after`` (2 s) after c.  A clear change already stands out on a shorter window:
the pre-look scores the newest position q with B = [q, q + S) (S = ``after`` of this object,
shorter than the full look's), ``short(q, S)``, as soon as those blocks have arrived, and
sends q at once when

- ``short(q, S)`` >= ``level`` x the detector's threshold (a strong change: weaker ones,
  more often a behaviour's own phase seen through a short window, wait for the full look);
- it exceeds ``short(q', S)`` for every q' in [q - reach, q) (the maximum of the profile on
  that length so far); and
- every position c' in (q, q + reach] that has at least ``shortest`` blocks of after window,
  L = S - (c' - q), scores ``short(c', L)`` < ``ratio`` x ``short(q, L)``: the positions
  after it, on the after windows they have, lie lower than q on the same lengths (the rule
  of ``rtseg.detectors.confirm``, whose ``reach`` and ``shortest`` it shares).

Every other change is still found by the full look (and its confirmation); a cut the
pre-look sent keeps the full look's maxima ``min_gap`` away (``CutSender.send_now``), so a
change is sent once.  All lengths in blocks of the detector (``step`` frames).  This object
holds the rule and counts what it sent (``sent``); the contrasts come from the detector.
"""

from __future__ import annotations

from typing import Callable


class PreLook:
    """The rule of the module docstring.  after, reach, shortest: blocks (after 0 = off);
    level: factor of the detector's threshold; ratio: in (0, 1]."""

    def __init__(self, after: int, level: float, ratio: float, reach: int, shortest: int) -> None:
        if after < 0 or reach < 0 or shortest < 1:
            raise ValueError(f"pre-look after window and reach must be >= 0 and its shortest "
                             f"window >= 1 block (got {after}, {reach}, {shortest})")
        if after and not reach:
            raise ValueError("the pre-look needs the short-look confirmation's reach "
                             "(confirm_reach_s > 0)")
        if not 0.0 < ratio <= 1.0:
            raise ValueError(f"pre_ratio must be in (0, 1], got {ratio}")
        if not level > 0.0:
            raise ValueError(f"pre_level must be > 0, got {level}")
        self.after, self.reach, self.shortest = int(after), int(reach), int(shortest)
        self.level, self.ratio = float(level), float(ratio)
        #: changes this rule sent
        self.sent = 0

    @property
    def on(self) -> bool:
        """Whether the rule is in use (``after`` > 0)."""
        return self.after > 0

    def value(self, q: int, threshold: float, first: int,
              short: Callable[[int, int], float], v: float | None = None) -> float | None:
        """The pre-look value of block position q when the rule sends it, else None.
        ``first``: the first block position with a value; ``short(c, L)``: the contrast at c
        with an after window of L blocks (all of whose blocks have arrived); ``v``: q's own
        value, ``short(q, after)``, when the caller has it already."""
        S = self.after
        if v is None:
            v = short(q, S)
        if not v >= self.level * threshold:
            return None
        for c in range(max(first, q - self.reach), q):
            if short(c, S) >= v:
                return None
        for c in range(q + 1, q + self.reach + 1):
            L = S - (c - q)
            if L < self.shortest:
                break
            if short(c, L) >= self.ratio * short(q, L):
                return None
        self.sent += 1
        return v
