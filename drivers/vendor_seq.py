"""Sequence gaps of the vendor suit streams (MVN sample counter, mocopi ``fnum``, Axis binary
frame index): frames a sender numbered but that never arrived.

:class:`SeqGaps` follows the counter of the frames a source delivers; :meth:`SeqGaps.step`
returns how many were skipped (``seq - last - 1`` for a forward jump of at most
``max_gap`` + 1).  A source adds 1 to ``stats.gaps`` and the count to ``stats.dropped`` per
jump, as the serial source does.  A jump backwards, or forward by more than ``max_gap``
frames (default 65 535: 4.5 minutes at 240 Hz), is a discontinuity - a sender restart, or
a damaged counter (these formats carry no checksum) - not a count of lost frames: it
returns 0 and adds 1 to ``discontinuities``.
"""

from __future__ import annotations

__all__ = ["SeqGaps"]


class SeqGaps:
    """Counter of ``bits`` bits (wrapping) -> frames missing before each new value."""

    def __init__(self, bits: int = 32, max_gap: int = 65535) -> None:
        self._mask = (1 << bits) - 1
        self.max_gap = int(max_gap)
        self.last: int | None = None
        #: jumps taken as a restart or a damaged counter (not counted as lost frames)
        self.discontinuities = 0

    def step(self, seq: int) -> int:
        """Frames missing between the previous value and ``seq`` (0 for the first)."""
        last, self.last = self.last, seq
        if last is None:
            return 0
        d = (seq - last) & self._mask
        if d <= 1:
            return 0
        if d - 1 > self.max_gap:
            self.discontinuities += 1
            return 0
        return d - 1
