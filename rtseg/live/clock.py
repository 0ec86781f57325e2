"""The session clock: one time scale for everything a live session reports.

Cut, behaviour, dropout and status times on the console, in JSON lines, over OSC and in
the recording are all **session seconds** from :class:`SessionClock`: seconds since the
session started, on the source's own clock when its frames carry one (``source_time``:
the serial suit's device clock, VMC's ``/VMC/Ext/T``, a replay's take clock), else on the
receive clock.  A replay sent 4 times faster than real time (``--speed 4``) therefore
reports the take's seconds, and frames lost on the way do not shift later times (the
source clock counts them; a count of frames received would not).  Wall-clock time is used
only for latencies and for silences, where no frame carries a time.

How frames map to session seconds (``feed``, called for every frame processed, in order):

- the first frame is at its arrival, ``recv - session_start`` (>= 0);
- each later frame with a source time is placed by the source clock's step ``ds`` since
  the last frame that had one (so a frame without a time in between shifts nothing);
  a frame without a time is placed by the receive clock's step ``dr`` from the previous
  frame (a source without a clock runs on the receive clock throughout);
- where the source clock's step cannot be trusted, the receive clock's step is used and a
  new **clock segment** begins (counted in ``segments``, warned by the session): it went
  back (``ds < 0``) or jumped ahead far beyond what the receive clock saw
  (``ds > 100 dr + 1 s``);
- no frame is placed before a moment already reported (``now(t, report=True)``: a status
  or a dropout sent during a silence): after a sender restart whose clock continues from
  its last time, the frames follow the silence the session reported.

Reported times therefore never go back.  ``now(t)`` is the time of the latest frame fed,
plus the wall-clock time since it arrived once that exceeds ``silence_s`` (while frames
flow it is the latest frame's time, so a status or a decision made on a frame carries
that frame's time; a reader that waits a moment for a core shifts nothing).  ``time_of(index)`` is a processed frame's time; a frame no longer
held (or never processed) is placed from a later one, one nominal frame period per frame.

Thread use: ``feed`` and ``time_of`` on the processing thread; ``now`` from any thread
(it reads one tuple, replaced whole).
"""

from __future__ import annotations

import math

import numpy as np

#: the source clock may run this many times faster than frames arrive (accelerated
#: replays) before a step is taken as a jump
MAX_SPEEDUP = 100.0


class SessionClock:
    """Session seconds of frames and of moments (see the module docstring).

    session_start: monotonic seconds at which the session started.
    frame_rate: nominal frames per second (places frames not held).
    capacity: frames whose times are kept for ``time_of`` (the ring buffer's capacity).
    silence_s: seconds without frames after which ``now`` follows the wall clock.
    """

    def __init__(self, session_start: float, frame_rate: float, capacity: int = 4096,
                 silence_s: float = 0.5) -> None:
        self.session_start = float(session_start)
        self.period = 1.0 / float(frame_rate)
        self.silence_s = float(silence_s)
        self._index = np.full(int(capacity), -1, dtype=np.int64)
        self._time = np.zeros(int(capacity), dtype=np.float64)
        #: (index, session s, monotonic receive time) of the latest frame fed
        self._last: tuple[int, float, float] | None = None
        #: (session s, source s, monotonic receive time) of the latest frame with a time
        self._anchor: tuple[float, float, float] | None = None
        self._floor = 0.0                     # the latest moment reported
        #: clock segments begun after the first (the source clock could not be followed)
        self.segments = 0
        #: why the last segment began ("" before any)
        self.last_break = ""

    def feed(self, index: int, recv: float, source_time: float | None) -> float:
        """The session time of frame ``index`` (received at monotonic ``recv``, source
        clock ``source_time`` s or None/NaN), fed in order; kept for ``time_of``."""
        src = source_time if source_time is not None and math.isfinite(source_time) else None
        last = self._last
        if last is None:
            t = max(0.0, recv - self.session_start)
        else:
            _, t_prev, recv_prev = last
            t = t_prev + max(0.0, recv - recv_prev)       # the receive clock's step
            anchor = self._anchor
            if src is not None and anchor is not None:
                a_t, a_src, a_recv = anchor
                ds, dr = src - a_src, max(0.0, recv - a_recv)
                why = ""
                if ds < 0.0:
                    why = f"the source clock went back {-ds:.6g} s"
                elif ds > MAX_SPEEDUP * dr + 1.0:
                    why = f"the source clock jumped {ds:.6g} s in {dr:.3f} s"
                if why:
                    self.segments += 1
                    self.last_break = why
                else:
                    t = max(a_t + ds, t_prev)
            t = max(t, self._floor)
        if src is not None:
            self._anchor = (t, src, float(recv))
        k = index % len(self._index)
        self._index[k] = index
        self._time[k] = t
        self._last = (int(index), t, float(recv))
        return t

    def time_of(self, index: int, at_index: int | None = None) -> float:
        """Session time of processed frame ``index``; one not held is placed ``at_index``
        (a later processed frame, default the latest) minus one frame period per frame."""
        k = index % len(self._index)
        if self._index[k] == index:
            return float(self._time[k])
        if at_index is not None:
            ka = at_index % len(self._index)
            if self._index[ka] == at_index:
                return float(self._time[ka]) - (at_index - index) * self.period
        last = self._last
        if last is None:
            return 0.0
        return last[1] - (last[0] - index) * self.period

    def now(self, monotonic: float, report: bool = False) -> float:
        """Session time of the moment ``monotonic`` (s): the latest frame's time, plus
        the wall-clock time since it arrived once that exceeds ``silence_s``; before any
        frame, ``monotonic - session_start``.  ``report``: the time goes out in an event
        (processing thread only), so no later frame is placed before it."""
        last = self._last
        if last is None:
            t = max(0.0, monotonic - self.session_start)
        else:
            since = monotonic - last[2]
            t = last[1] + (since if since > self.silence_s else 0.0)
        if report and t > self._floor:
            self._floor = t
        return t

    @property
    def latest(self) -> tuple[int, float, float] | None:
        """(index, session s, monotonic receive time) of the latest frame fed, or None."""
        return self._last


__all__ = ["SessionClock", "MAX_SPEEDUP"]
