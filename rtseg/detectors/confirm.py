"""Short-look confirmation: send a full-look maximum of the contrast detector
(``rtseg.detectors.contrast``) as soon as the positions just after it, scored with their after
windows cut short at the newest frame, say it is the maximum, instead of waiting for the
profile to fall.

The peak picker (``rtseg.detectors.peaks``) confirms a maximum at c once the full contrast
falls below ``drop`` x its value or ``hold`` later positions brought nothing higher.  A
position's full value is known only ``after`` (B's length) after it, so that confirmation
comes a median 0.45 s after the maximum's own value: the cuts' delay is the after window
plus that wait.  The positions just after c already have most of their after windows:
with the newest block n, position c' > c has n - c' blocks of it.  Scored on those
(``short(c', L)``: the same contrast with B = [c', c' + L)) and compared with the maximum
scored on the same length, a later position that lies nearer the change scores higher -
its short B holds only the new behaviour, c's short B also some of the old - while a
maximum at the change scores highest.  So the maximum at block c is sent at block n when

    short(c', n - c') < ``ratio`` x short(c, n - c')   for every c' in (c_full, c + reach]

(c_full: the newest position with a full value, all of them already below the maximum;
every n - c' at least ``shortest`` blocks), and only for maxima of at least ``level`` x the
detector's threshold: weaker maxima, more often a rising flank or a behaviour's own phase,
wait for the full look as before.  With the shipped lengths (after window 2 s, reach 1 s,
shortest 1 s) the first chance to send is the maximum's own full look, 2 s after it.

With ``clear`` > 0 a maximum is sent this way only when it stands clear of the profile
before it: its full value at least ``clear`` x the highest full value of the positions
[c_full - ``span``, c - ``reach``) (``span``: the detector's before window, counted back
from the newest full value, so a maximum asked again later looks at less before it; the
``reach`` just before c, the change's own rising flank, left out).  Inside a behaviour whose motion varies
(a dribble, a dance) the profile rises and falls at every phase, and a maximum there lies
not far above the ones before it; it waits for the profile to fall, as without this rule.
The threshold is the stream's own profile, so nothing here is fitted to a source.

All lengths in blocks of the detector (``step`` frames).  The contrasts come from the
detector (``short``); this object holds the rule and counts what it sent (``sent``).
"""

from __future__ import annotations

from collections import deque
from typing import Callable


class ShortConfirmation:
    """The rule of the module docstring.  reach, shortest, span: blocks (reach 0 = off);
    level: factor of the detector's threshold; ratio: in (0, 1]; clear: 0 (off) or >= 1."""

    def __init__(self, reach: int, shortest: int, level: float = 0.0, ratio: float = 1.0,
                 clear: float = 0.0, span: int = 0) -> None:
        if reach < 0 or shortest < 1:
            raise ValueError(f"short-look reach must be >= 0 and its shortest window >= 1 "
                             f"block (got {reach}, {shortest})")
        if not 0.0 < ratio <= 1.0:
            raise ValueError(f"confirm_ratio must be in (0, 1], got {ratio}")
        if not level >= 0.0:
            raise ValueError(f"confirm_level must be >= 0, got {level}")
        if not (clear == 0.0 or clear >= 1.0):
            raise ValueError(f"confirm_clear must be 0 (off) or >= 1, got {clear}")
        if clear and span <= reach:
            raise ValueError(f"confirm_clear needs a before span longer than the reach "
                             f"(got {span} and {reach} blocks)")
        self.reach, self.shortest = int(reach), int(shortest)
        self.level, self.ratio = float(level), float(ratio)
        self.clear, self.span = float(clear), int(span)
        #: (block position, full value) of the newest ``span`` + 1 positions, for ``clear``
        self._profile: deque[tuple[int, float]] = deque(maxlen=max(1, self.span + 1))
        #: maxima this rule sent; maxima it left to the fall for not standing clear
        self.sent = 0
        self.unclear = 0

    def reset(self) -> None:
        """Forget the profile (the detector restarted: block positions start again)."""
        self._profile.clear()

    def note(self, c: int, value: float) -> None:
        """The full value at block c (positions in increasing order), for ``clear``."""
        if self.clear:
            self._profile.append((c, value))

    def stands_clear(self, c: int, value: float, newest_full: int) -> bool:
        """Whether ``value`` at block c is at least ``clear`` x every full value of
        [newest_full - span, c - reach) (True when off or none is known)."""
        if not self.clear:
            return True
        lo, hi = newest_full - self.span, c - self.reach
        before = [v for p, v in self._profile if lo <= p < hi]
        return not before or value >= self.clear * max(before)

    @property
    def on(self) -> bool:
        """Whether the rule is in use (``reach`` > 0)."""
        return self.reach > 0

    def first_block(self, c: int) -> int:
        """The first newest block at which a maximum at block c can be sent."""
        return c + self.reach + self.shortest

    def confirms(self, c: int, value: float, threshold: float, newest_full: int,
                 newest: int, full_len: int, short: Callable[[int, int], float]) -> bool:
        """Whether the maximum at block c (full value ``value``) is confirmed with the
        blocks up to ``newest`` (exclusive) arrived: ``newest_full`` is the newest position
        with a full value, ``full_len`` the full after window (blocks), ``short(c', L)``
        the contrast at c' with an after window of L blocks."""
        if not self.on or value < self.level * threshold or newest < self.first_block(c):
            return False
        if not self.stands_clear(c, value, newest_full):
            self.unclear += 1
            return False
        ref: dict[int, float] = {}
        for c2 in range(newest_full + 1, c + self.reach + 1):
            L = newest - c2
            if L >= full_len:
                continue
            if L not in ref:
                ref[L] = short(c, L)
            if short(c2, L) >= self.ratio * ref[L]:
                return False
        self.sent += 1
        return True
