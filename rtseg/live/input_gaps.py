"""Gaps in a live input, counted from one frame to the next (``rtseg.live.pipeline``): the
frames missing by the source's sequence numbers (u16 wraps, restarts) and by its own clock
(for sources whose numbers cannot show a loss, as VMC's), and the silence since the
previous frame, in seconds of the receiver's monotonic clock."""

from __future__ import annotations

import math

#: a source-clock step longer than this (s) is no run of lost frames but a clock that jumped
#: (a damaged or reset timestamp): it counts no missing frames and teaches no period
MAX_STEP_S = 86400.0


class InputGaps:
    """The previous frame's sequence number, receive time and source time, and the source
    clock's learned frame period.  ``max_gap_frames``: a backwards sequence jump counts as
    this many + 1 missing frames (beyond any bridge)."""

    def __init__(self, max_gap_frames: int) -> None:
        self.max_gap_frames = int(max_gap_frames)
        self._prev_seq: int | None = None
        self._prev_recv: float | None = None
        self._prev_src: float | None = None
        self._src_period: float | None = None
        self._src_steps = 0
        self._src_long = 0

    def step(self, seq: int | None, recv_time: float | None, source_time: float | None,
             lost: int = 0) -> tuple[int, float]:
        """(frames missing just before this frame, seconds since the previous one): the
        largest of the sequence gap, the source-clock gap and ``lost`` (frames the live
        loop lost or dropped; all are between the previous frame and this one, and a
        sequence gap includes the frames dropped); then this frame is the previous one."""
        lost = max(0, int(lost))
        missing = max(self.seq_missing(seq), self.time_missing(source_time, lost), lost)
        silence = (recv_time - self._prev_recv
                   if recv_time is not None and self._prev_recv is not None else 0.0)
        if seq is not None:
            self._prev_seq = int(seq)
        if recv_time is not None:
            self._prev_recv = float(recv_time)
        if source_time is not None and math.isfinite(source_time):
            self._prev_src = float(source_time)
        return missing, silence

    def seq_missing(self, seq: int | None) -> int:
        """Frames missing between the previous sequence number and ``seq``.

        A backwards jump (device restart) counts as a gap beyond any limit; a jump back by
        more than half of 16 bits from near the top is taken as a u16 wrap.
        """
        prev = self._prev_seq
        if seq is None or prev is None:
            return 0
        d = seq - prev
        if d <= 0 and prev < 65536 and seq < 65536 and prev - seq > 32768:
            d += 65536
        if d <= 0:
            return self.max_gap_frames + 1 if d < 0 else 0
        return d - 1

    def time_missing(self, source_time: float | None, known_lost: int = 0) -> int:
        """Frames missing according to the source's clock, for sources whose sequence
        numbers cannot show a loss (VMC numbers the frames it assembles).

        The frame period is learned from the source's own time steps (running mean of the
        steps that are not gaps, after 16 steps), so it does not depend on the nominal
        rate.  Returns 0 until then, for steps backwards (clock reset), for steps longer
        than ``MAX_STEP_S`` (a clock jump) and for steps below 2.5 periods; after 8 long
        steps in a row the source is taken to have slowed down and the period is learned
        again.  A step over frames the caller knows are lost
        (``known_lost`` > 0: dropped by the live loop) is measured but not learned from."""
        prev = self._prev_src
        if source_time is None or prev is None or not math.isfinite(source_time):
            return 0
        d = source_time - prev
        if not 0 < d <= MAX_STEP_S:      # back, repeated, or a jump (even past float range)
            return 0
        p = self._src_period
        if known_lost > 0:
            return 0 if p is None else max(0, int(round(d / p)) - 1)
        if p is None:
            self._src_period, self._src_steps = d, 1
            return 0
        if d < 2.5 * p or self._src_steps < 16:
            self._src_period = p + (d - p) / min(self._src_steps + 1, 64)
            self._src_steps += 1
            self._src_long = 0
            return 0
        self._src_long += 1
        if self._src_long >= 8:          # the source slowed down for good: new period
            self._src_period, self._src_steps, self._src_long = d, 1, 0
            return 0
        return max(0, int(round(d / p)) - 1)
