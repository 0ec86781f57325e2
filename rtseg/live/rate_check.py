"""Checking a source's declared frame rate against the frames that arrive.

:class:`DeclaredRateCheck` watches the first ``window_s`` seconds (source clock when frames
carry ``source_time``, else the receive clock) of a session whose source declared a nominal
rate (``rate=`` in the URL).  The measured rate is frames elapsed per second, frames elapsed
taken from ``seq`` when frames carry it (so frames lost on the way do not lower it), else
from the count of frames received.  A measured rate off the declared one by more than
``tolerance`` (a fraction, default 0.10) is a mismatch: the live loop logs one warning and
keeps the declared rate (an accelerated replay declares the take's rate on purpose), so
window lengths and times stay as declared.
"""

from __future__ import annotations

import math


class DeclaredRateCheck:
    """Feed every frame (``feed``); returns a message once, when the declared rate is off."""

    def __init__(self, declared_hz: float, window_s: float = 2.0,
                 tolerance: float = 0.10) -> None:
        self.declared_hz = float(declared_hz)
        self.window_s = float(window_s)
        self.tolerance = float(tolerance)
        self.done = False
        #: the measured rate (Hz) once the window is full, else None
        self.measured_hz: float | None = None
        self._t0: float | None = None
        self._seq0: int | None = None
        self._n = 0
        self._use_source: bool | None = None

    def feed(self, recv: float, source_time: float | None, seq: int | None) -> str | None:
        """One frame (receive time s, source time s or None, sequence number or None)."""
        if self.done:
            return None
        if self._use_source is None:
            self._use_source = source_time is not None and math.isfinite(source_time)
        t = source_time if self._use_source else recv
        if t is None or not math.isfinite(t):
            return None
        if self._t0 is None:
            self._t0, self._seq0, self._n = t, seq, 0
            return None
        self._n += 1
        span = t - self._t0
        if span < 0:                       # the clock restarted: measure afresh
            self._t0, self._seq0, self._n = t, seq, 0
            return None
        if span < self.window_s:
            return None
        self.done = True
        frames = (seq - self._seq0) if (seq is not None and self._seq0 is not None
                                        and seq > self._seq0) else self._n
        self.measured_hz = frames / span
        if abs(self.measured_hz - self.declared_hz) <= self.tolerance * self.declared_hz:
            return None
        clock = "source" if self._use_source else "receive"
        return (f"declared rate={self.declared_hz:g} Hz but frames arrive at "
                f"{self.measured_hz:.1f} Hz (measured over {span:.1f} s of {clock} time); "
                f"the declared rate is kept; fix rate= in the source URL unless this is "
                f"an accelerated replay")


__all__ = ["DeclaredRateCheck"]
