"""Sequence gaps of the vendor suit streams (MVN sample counter, mocopi ``fnum``, Axis binary
frame index): frames a sender numbered but that never arrived.

:class:`SeqGaps` follows the counter of the frames a source delivers; :meth:`SeqGaps.step`
returns a :class:`SeqStep`: the frames lost just before this one, the ``seq`` to deliver
and the counter jumps to count.  A source adds 1 to ``stats.gaps`` and ``missing`` to
``stats.dropped`` per gap, as the serial source does, and ``jumps`` to
``stats.counter_jumps``.

These formats carry no checksum, so a damaged byte of the counter reaches the receiver as a
valid-looking number, and a counter is only believed as far as the receive clock explains
it.  ``rate``: the counter's rate measured on the receive clock (frames per second over
windows of ``RATE_WINDOW_S``; ``MAX_RATE`` until measured), ``elapsed``: receive seconds
since the last trusted value.  A forward jump skipping ``k`` frames is

- a **gap**, counted at once, if ``k <= MIN_SLACK + 2 * rate * elapsed`` (what the time
  that passed explains);
- a **probable gap** if ``k <= rate * (SLACK_S + 2 * elapsed)`` (at most ``max_gap``): a
  receiver that stalled reads the frames around a gap at once, but so does a damaged byte
  look: the value waits for the next frame (below) and is counted as a gap only if the
  stream goes on from it;
- a **suspect** value beyond that, as is a jump backwards by more than ``MIN_SLACK`` (one
  at most ``MIN_SLACK`` back, or a repeat, is a frame that arrived late: it changes
  nothing, and the source drops it, counted in ``bad_messages``: ``SeqStep.late``).  A
  suspect value is a counter jump (1 in ``jumps``) and never a count of lost frames.

A frame with a probable-gap or suspect value is delivered - its payload is whole, only its
number is doubtful - with ``seq`` = its value for a probable gap (most likely true), the
last trusted value + 1 (+ 1 per further waiting frame) for a suspect one, and the next value
decides, from whichever of the last trusted value and the waiting one it follows closer:

- it goes on from the last trusted value: the waiting value was a damaged counter (1 in
  ``jumps`` for a probable gap; a suspect was counted when it came) and the gap from the
  trusted value leaves out the frames that arrived in between (``100, 23189, 102`` counts
  nothing in ``dropped``: neither the jump forward nor the jump back);
- it goes on from the waiting value: a probable gap is confirmed and counted; after a
  suspect the sender's counter really jumped (a restart): the counter is re-anchored there
  and only frames skipped after it count (``1000, 0, 1``: 1 counter jump, nothing dropped);
- neither: it waits in turn.

Counter jumps are logged at most every ``LOG_EVERY_S`` s (re-anchorings likewise, at INFO),
with the number of messages left out.
"""

from __future__ import annotations

import logging
import math
import time
from typing import NamedTuple

__all__ = ["SeqGaps", "SeqStep", "SLACK_S", "MAX_RATE", "MIN_SLACK"]

#: seconds of frames a probable gap may exceed the receive time elapsed by (a receiver
#: that stalled reads the frames around a gap at once)
SLACK_S = 2.0
#: counter rate (Hz) assumed until the stream's rate is measured (above any suit's)
MAX_RATE = 1000.0
#: frames a gap may exceed the receive clock by and still count at once; also how far
#: back a value is a late frame rather than a damaged counter
MIN_SLACK = 16
#: receive seconds over which the counter's rate is measured
RATE_WINDOW_S = 1.0
#: counter jumps are logged at most this often (s), with the count left out
LOG_EVERY_S = 10.0

_log = logging.getLogger("rtseg.drivers")


class SeqStep(NamedTuple):
    """What one counter value means: ``missing`` frames lost just before it (0 or more),
    ``seq`` to deliver (the value, or for a suspect one the last trusted value + the frames
    waiting since), ``jumps``: counter values now taken as damaged or restarted counters (0-2;
    count them), ``late``: the value repeats the last one or lies at most ``MIN_SLACK``
    behind it - a frame repeated or reordered on the way, whose time has passed: drop it
    (count it in ``bad_messages``), its ``seq`` would go back."""
    missing: int
    seq: int
    jumps: int = 0
    late: bool = False


class SeqGaps:
    """Counter of ``bits`` bits (wrapping) -> frames missing before each new value.

    ``max_gap``: the largest count of lost frames one jump can stand for.  ``name`` and
    ``counter`` name the source and its counter in the log messages (``"mocopi"``,
    ``"fnum"``); ``logger``: where they go.
    """

    def __init__(self, bits: int = 32, max_gap: int = 65535, *, name: str = "",
                 counter: str = "counter", logger: logging.Logger | None = None) -> None:
        self._mask = (1 << bits) - 1
        self._half = 1 << (bits - 1)
        self.max_gap = int(max_gap)
        self.name = name
        self.counter = counter
        self._log = logger if logger is not None else _log
        #: the last trusted value (None before the first)
        self.last: int | None = None
        self._t_last: float | None = None
        #: the value waiting for the next one to decide (a probable gap or a suspect), or
        #: None; ``pending_gap``: it is a probable gap (not yet counted as a jump)
        self.pending: int | None = None
        self.pending_gap = False
        self._t_pending: float | None = None
        #: frames delivered since ``last`` with a waiting value
        self._held = 0
        #: counter rate measured on the receive clock (frames/s) or None
        self.rate: float | None = None
        self._win_t: float | None = None
        self._win_adv = 0
        self._win_rate: float | None = None
        #: values taken as damaged or restarted counters (not lost frames)
        self.discontinuities = 0
        #: re-anchorings: the stream went on from a suspect value
        self.restarts = 0
        self._logged_at: dict[int, float] = {}
        self._unlogged: dict[int, int] = {}

    def bounds(self, elapsed: float | None) -> tuple[int, int]:
        """(largest gap counted at once, largest probable gap) in frames skipped,
        ``elapsed`` receive seconds after the previous value (None: no receive clock, every
        probable gap counts at once)."""
        rate = self.rate if self.rate is not None else MAX_RATE
        e = max(0.0, elapsed) if elapsed is not None and math.isfinite(elapsed) else 0.0
        probable = min(self.max_gap, max(MIN_SLACK, math.ceil(rate * (SLACK_S + 2.0 * e))))
        if elapsed is None:
            return probable, probable
        return min(probable, MIN_SLACK + math.ceil(2.0 * rate * e)), probable

    def step(self, seq: int, now: float | None = None) -> SeqStep:
        """The value ``seq`` of the next frame, received at ``now`` (monotonic s; None: no
        receive clock, only the fixed bounds apply)."""
        seq = int(seq) & self._mask
        last = self.last
        if last is None:
            self._accept(seq, now, 0)
            return SeqStep(0, seq)
        d = (seq - last) & self._mask
        if d == 1 and self.pending is None:            # the usual case
            self._accept(seq, now, 1)
            return SeqStep(0, seq)
        if d == 0 or self._mask + 1 - d <= MIN_SLACK:  # repeated, or a few frames late
            return SeqStep(0, seq, 0, True)
        sure, probable = self.bounds(_elapsed(now, self._t_last))
        k = d - 1 - self._held                          # waiting frames filled some slots
        from_last = d < self._half and k <= probable
        p = self.pending
        if p is not None:
            dp = (seq - p) & self._mask
            if 0 < dp < self._half and (not from_last or dp < d) and \
                    dp - 1 <= self.bounds(_elapsed(now, self._t_pending))[1]:
                return self._resolve(seq, now, p, dp)
        # a new value waiting replaces the one before: that one was no gap
        refuted = int(p is not None and self.pending_gap)
        self.discontinuities += refuted
        if from_last and k <= sure:
            self._accept(seq, now, d)
            return SeqStep(max(0, k), seq, refuted)
        self.pending, self._t_pending = seq, now
        self._held += 1
        self.pending_gap = from_last
        if from_last:
            self._note(now, f"{self.counter} {seq} after {last}: {k} frame(s) skipped "
                            "faster than the receive clock explains; counted when the "
                            "next frame confirms it", logging.INFO)
            return SeqStep(0, seq, refuted)
        self.discontinuities += 1
        self._note(now, f"{self.counter} {seq} after {last}: taken as a damaged or restarted "
                        f"counter, not as lost frames (counted in counter_jumps)")
        return SeqStep(0, (last + self._held) & self._mask, 1 + refuted)

    # -- internals

    def _resolve(self, seq: int, now: float | None, p: int, dp: int) -> SeqStep:
        """``seq`` goes on from the waiting value ``p``: a probable gap is confirmed, a
        suspect value re-anchors the counter."""
        last = self.last
        if self.pending_gap:
            missing = max(0, ((p - last) & self._mask) - 1 - (self._held - 1)) + dp - 1
            self._accept(seq, now, (seq - last) & self._mask)
            return SeqStep(missing, seq)
        self.restarts += 1
        self._note(now, f"{self.counter} went on from {p} ({seq}) after {last}: counter "
                        "re-anchored there", logging.INFO)
        self._win_t, self._win_adv = now, 0
        self._accept(seq, now, 0)
        return SeqStep(dp - 1, seq)

    def _accept(self, seq: int, now: float | None, advance: int) -> None:
        self.last, self._t_last = seq, now
        self.pending, self.pending_gap, self._t_pending, self._held = None, False, None, 0
        if now is None:
            return
        if self._win_t is None:
            self._win_t, self._win_adv = now, 0
            return
        self._win_adv += advance
        span = now - self._win_t
        if span >= RATE_WINDOW_S:
            r = self._win_adv / span
            # the larger of two windows: one spanning a pause of the sender reads low
            self.rate = max(r, self._win_rate) if self._win_rate is not None else r
            self._win_rate = r
            self._win_t, self._win_adv = now, 0
        elif span < 0:                                  # receive clock went back
            self._win_t, self._win_adv = now, 0

    def _note(self, now: float | None, message: str, level: int = logging.WARNING) -> None:
        """Log ``message`` at most every ``LOG_EVERY_S`` s per level, with the number of
        messages of that level left out since."""
        t = now if now is not None else time.monotonic()
        at = self._logged_at.get(level, -math.inf)
        if at <= t < at + LOG_EVERY_S:
            self._unlogged[level] = self._unlogged.get(level, 0) + 1
            return
        n = self._unlogged.pop(level, 0)
        more = f" ({n} more since the last message)" if n else ""
        self._logged_at[level] = t
        self._log.log(level, "%s%s%s", f"{self.name}: " if self.name else "", message, more)


def _elapsed(now: float | None, then: float | None) -> float | None:
    return None if now is None or then is None else now - then
