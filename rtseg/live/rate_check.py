"""Checking a source's declared frame rate against the frames that arrive.

:class:`DeclaredRateCheck` watches the first ``window_s`` seconds (source clock when frames
carry ``source_time``, else the receive clock) of a session whose source declared a nominal
rate (``rate=`` in the URL), or of one whose source declared none (``assumed``: the
session's default rate is checked the same way, and the warning says no rate was declared).  The measured rate is frames elapsed per second, frames elapsed
taken from ``seq`` when frames carry it (so frames lost on the way do not lower it), else
from the count of frames received.  A measured rate off the declared one by more than
``tolerance`` (a fraction, default 0.10) is a mismatch, warned once:

- measured on the **source clock** (the sender's own timestamps: they say how many frames
  a second of motion holds, at any sending speed), the live session **uses the measured
  rate** from then on (:func:`switch_rate`): its detectors and identity tracker are built
  again at that rate and given the frames received so far again, so windows in seconds
  hold the seconds they should (a VMC sender at 120 Hz read as ``rate=60`` cut 8 times
  where 6 changes were);
- measured on the **receive clock** (the frames carry no time), the declared rate is
  kept: an accelerated replay without timestamps declares its take's rate on purpose.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

log = logging.getLogger("rtseg.live.session")

#: measured rates outside this range (Hz) are not believed (a damaged clock): the session
#: keeps its rate
MIN_HZ, MAX_HZ = 5.0, 5000.0


class DeclaredRateCheck:
    """Feed every frame (``feed``); returns a message once, when the declared rate is off."""

    def __init__(self, declared_hz: float, window_s: float = 2.0,
                 tolerance: float = 0.10, assumed: bool = False) -> None:
        self.declared_hz = float(declared_hz)
        #: the source declared no rate: ``declared_hz`` is the session's assumption
        self.assumed = bool(assumed)
        self.window_s = float(window_s)
        self.tolerance = float(tolerance)
        self.done = False
        #: the measured rate (Hz) once the window is full, else None
        self.measured_hz: float | None = None
        self._t: float | None = None                # the last frame's time (measured clock)
        self._seq: int | None = None
        self._periods: list[float] = []             # seconds per frame, frame to frame
        self._t0: float | None = None               # the first frame's time and seq
        self._seq0: int | None = None
        self._n = 0                                 # frames since the first
        self._use_source: bool | None = None

    @property
    def on_source_clock(self) -> bool:
        """Whether the rate is measured on the frames' own clock (``source_time``)."""
        return bool(self._use_source)

    @property
    def mismatch(self) -> bool:
        """Whether the measured rate (once known, and believable) is off the declared one."""
        return (self.measured_hz is not None and MIN_HZ <= self.measured_hz <= MAX_HZ
                and abs(self.measured_hz - self.declared_hz) > self.tolerance * self.declared_hz)

    def feed(self, recv: float, source_time: float | None, seq: int | None) -> str | None:
        """One frame (receive time s, source time s or None, sequence number or None).

        On the source clock the rate is 1 / the median of the frame-to-frame periods (time
        step over sequence step), so a few damaged timestamps or a clock that restarts do
        not move it; the window is full once the periods span ``window_s`` at the median
        period.  On the receive clock (frames come in bursts) it is the frames elapsed over
        the time elapsed since the first frame."""
        if self.done:
            return None
        if self._use_source is None:
            self._use_source = source_time is not None and math.isfinite(source_time)
        t = source_time if self._use_source else recv
        if t is None or not math.isfinite(t):
            return None
        prev_t, prev_seq = self._t, self._seq
        self._t, self._seq = t, seq
        if prev_t is None:
            self._t0, self._seq0 = t, seq
            return None
        self._n += 1
        if self._use_source:
            steps = (seq - prev_seq) if (seq is not None and prev_seq is not None
                                         and seq > prev_seq) else 1
            if t > prev_t:
                self._periods.append((t - prev_t) / steps)
            n = len(self._periods)
            if n < 8 or n % 8:
                return None
            period = float(np.median(self._periods))
            span = n * period
        else:
            span = t - self._t0
            frames = (seq - self._seq0) if (seq is not None and self._seq0 is not None
                                            and seq > self._seq0) else self._n
            period = span / frames if span > 0 else 0.0
        if span < self.window_s or not period > 0:
            return None
        self.done = True
        self.measured_hz = 1.0 / period
        if not MIN_HZ <= self.measured_hz <= MAX_HZ:
            return (f"the source's {'clock' if self._use_source else 'frames'} say "
                    f"{self.measured_hz:.3g} Hz, outside {MIN_HZ:g}-{MAX_HZ:g} Hz: not "
                    f"believed; the session keeps {self.declared_hz:g} Hz")
        if abs(self.measured_hz - self.declared_hz) <= self.tolerance * self.declared_hz:
            return None
        if self.assumed:
            what = (f"the source declares no frame rate (rtseg assumed "
                    f"{self.declared_hz:g} Hz)")
            if self._use_source:
                return (f"{what}; its clock says {self.measured_hz:.1f} Hz (measured over "
                        f"{span:.1f} s of its time): the session uses "
                        f"{round(self.measured_hz, 1):g} Hz from now on (detectors started "
                        f"again); add rate={round(self.measured_hz):g} to the source URL to "
                        f"start at it")
            return (f"{what}; frames arrive at {self.measured_hz:.1f} Hz (measured over "
                    f"{span:.1f} s of receive time; the frames carry no time): the assumed "
                    f"rate is kept; add rate= to the source URL")
        if self._use_source:
            return (f"declared rate={self.declared_hz:g} Hz but the source's clock says "
                    f"{self.measured_hz:.1f} Hz (measured over {span:.1f} s of its time); "
                    f"the session uses {round(self.measured_hz, 1):g} Hz from now on "
                    f"(detectors started again); fix rate= in the source URL")
        return (f"declared rate={self.declared_hz:g} Hz but frames arrive at "
                f"{self.measured_hz:.1f} Hz (measured over {span:.1f} s of receive time; "
                f"the frames carry no time); the declared rate is kept; fix rate= in the "
                f"source URL unless this is an accelerated replay")


def switch_rate(session: Any, rate: float, upto: int) -> None:
    """Run live session ``session`` at ``rate`` Hz from now on (processing thread): a new
    ``Pipeline`` (features, detectors, identity tracker) at that rate, given again the
    frames ``0 .. upto - 1`` the ring still holds (what they revealed was reported by the
    old pipeline already, or is not reported: nothing is sent twice), then the session's
    rate, clock period, wire methods, the recording's declared rate and the monitor follow."""
    from rtseg.live.outputs import wire_methods
    from rtseg.live.pipeline import Pipeline
    old = session.pipeline
    posture = old.posture          # the rig's geometry, or how to find it, carries over
    pipe = Pipeline(old.joint_names, old.parents, old.space, rate, session.config,
                    rest=posture.geometry if posture.geometry is not None else posture.rest,
                    standard=posture.standard)
    ring = session.ring
    J = len(old.joint_names)
    start = max(0, ring.oldest)
    if upto > start:
        w = ring.get(start, upto)
        for i in range(len(w)):
            seq = int(w.seq[i])
            src = float(w.source_time[i])
            pipe.process(w.start + i, w.data[i].reshape(J, 4), w.valid[i],
                         None if seq < 0 else seq, float(w.recv_time[i]),
                         0, src if np.isfinite(src) else None)
        if pipe.identity is not None:
            pipe.identity.drain()
    session.pipeline = pipe
    session.frame_rate = float(rate)
    session.clock.period = 1.0 / float(rate)
    session.primary, session.wire = wire_methods(session.config, pipe.detectors)
    header = getattr(session.recorder, "header", None)
    if isinstance(header, dict) and "frame_rate" in header:
        header["frame_rate"] = float(rate)
    if session.monitor is not None:
        session._monitor_call(session.monitor.attach)
    log.info("session: now at %g Hz (%d frames given again)", rate, max(0, upto - start))


__all__ = ["DeclaredRateCheck", "switch_rate"]
