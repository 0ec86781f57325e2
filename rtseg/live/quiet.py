"""The live session's side of quiet frames (``rtseg.live.loop``, "Quiet frames"): until
when the loop may leave a polled source unread because the frames due before then cannot
send anything, and the accounting of the batch read when that time comes.

:class:`SessionQuiet` is a part of :class:`rtseg.live.session.LiveSession` (a base class; it
uses the session's ``config``, ``source``, ``pipeline``, ``ring``, ``stats``,
``frame_rate``, ``_cursor``, ``_polled``, ``_stop`` and the last processed frame's
``_last_recv`` / ``_last_index`` / ``_last_clocked``, set by ``rtseg.live.process``).
Times are monotonic seconds.
"""

from __future__ import annotations

from rtseg.live.loop import MAX_DEFER_S


class SessionQuiet:
    """Quiet-frame batching of a :class:`~rtseg.live.session.LiveSession`."""

    def _begin_quiet(self) -> None:
        """The state, set up when the session begins."""
        self._batch_quiet = bool(self.config["buffer.batch_quiet"])
        self._last_clocked = False               # the last frame processed had a source time
        self._rate_ref: tuple[float, int] | None = None   # (recv time, index) a second ago
        self._arrival_period: float | None = None  # s between frames over the last second
        self._quiet_from = 0                      # ring index of the first frame left unread
        self._quiet_promised = 0                  # ... and how many of them are quiet

    def _quiet_until(self, now: float) -> float | None:
        """Until when (monotonic s) the loop may leave this session's source unread: the
        frames due before then cannot send anything (``rtseg.live.loop``, "Quiet
        frames").  None: read as frames arrive (frames waiting, a source read by a
        thread or one that cannot hold frames, frames without a source clock,
        ``buffer.batch_quiet`` off, or too few quiet frames)."""
        if (not self._batch_quiet or not self._polled
                or self._last_recv is None or not self._last_clocked
                or self._cursor.backlog > 0 or self._stop.is_set()):
            return None
        try:
            hold = int(self.source.hold_frames())
        except Exception:                      # pragma: no cover - a driver bug
            return None
        if hold <= 0:                          # a source that cannot hold frames
            return None
        # frames come at the nominal rate or faster (a replay sped up): the shorter period
        # of the two, the measured one over a second or more (none before that)
        ref = self._rate_ref
        if ref is None or self._last_index <= ref[1]:
            self._rate_ref = (self._last_recv, self._last_index)
        elif self._last_recv - ref[0] >= 1.0:
            self._arrival_period = (self._last_recv - ref[0]) / (self._last_index - ref[1])
            self._rate_ref = (self._last_recv, self._last_index)
        if self._arrival_period is None:
            return None
        period = min(1.0 / self.frame_rate, self._arrival_period)
        q = min(self.pipeline.quiet_frames(), hold)
        # the loop wakes half a period before the last quiet frame is due, so the frame
        # after it (which may send) is read as it arrives even when it comes up to 1.5
        # periods early
        until = self._last_recv + min((q - 0.5) * period, MAX_DEFER_S)
        if until - now < 2.0 * period:
            return None
        self._quiet_from = self.ring.head
        self._quiet_promised = q
        return until

    def _read_quiet(self, now: float) -> None:
        """The loop's read of what arrived while the source was left unread: counted in
        ``quiet_batches`` / ``quiet_frames``, and frames beyond the promised quiet ones
        (which could send, and so were read late) in ``late_open``."""
        self._poll_source(now)
        st = self.stats
        n = self.ring.head - self._quiet_from
        st.quiet_batches += 1
        st.quiet_frames += min(n, self._quiet_promised)
        st.late_open += max(0, n - self._quiet_promised)


__all__ = ["SessionQuiet"]
