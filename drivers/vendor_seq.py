"""Sequence gaps of the vendor suit streams (MVN sample counter, mocopi ``fnum``, Axis binary
frame index): frames a sender numbered but that never arrived.

:class:`SeqGaps` follows the counter of the frames a source delivers; :meth:`SeqGaps.step`
returns how many were skipped (``seq - last - 1`` for a forward jump of less than half the
counter range).  A source adds 1 to ``stats.gaps`` and the count to ``stats.dropped`` per
jump, as the serial source does.  A jump backwards, or forward by half the range or more,
is a sender restart (its counter starts over): not a gap.
"""

from __future__ import annotations

__all__ = ["SeqGaps"]


class SeqGaps:
    """Counter of ``bits`` bits (wrapping) -> frames missing before each new value."""

    def __init__(self, bits: int = 32) -> None:
        self._mask = (1 << bits) - 1
        self._half = 1 << (bits - 1)
        self.last: int | None = None

    def step(self, seq: int) -> int:
        """Frames missing between the previous value and ``seq`` (0 for the first)."""
        last, self.last = self.last, seq
        if last is None:
            return 0
        d = (seq - last) & self._mask
        return d - 1 if 1 < d < self._half else 0
