"""Recording a suit calibration from a live source (``rtseg calibrate``).

The performer holds a T-pose for a second, then bends the knees (a squat, walking on the
spot); :func:`capture` reads the source's frames meanwhile and tries
``rtseg.core.suit_calibration.calibrate`` on what has arrived every half second, until it
succeeds or ``seconds`` have passed.  A calibration needs every sensor: a sensor invalid
in a frame is taken at its last good value (which the source keeps in the frame) when it
was valid within :data:`STALE_S`, else the frame is left out.  The source must give
sensor orientations (``space``
"global") and must not be calibrated already (:func:`check_source`).

The hold is timed at the source's declared frame rate, unless the frames carry the
device's clock (``source_time``) and it says otherwise by more than 10 % (a 60 Hz suit
read without ``rate=60``): then at the measured rate (``Capture.measured_rate``), as the
live session switches to it (``rtseg.live.rate_check``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from rtseg.core.suit_calibration import (HOLD_S, CalibrationError, SuitCalibration, calibrate,
                                         still_stretch)
from rtseg.live.rate_check import DeclaredRateCheck

#: seconds of new frames between two attempts
TRY_EVERY_S = 0.5
#: seconds a sensor's last good value stands in for it (the serial source's ``stale``)
STALE_S = 0.25
#: seconds of the device's clock its rate is measured over (``DeclaredRateCheck``'s
#: window; the session's is 2 s, but the T-pose must be timed from its first second)
RATE_WINDOW_S = 0.25


@dataclass
class Capture:
    """What :func:`capture` saw: ``frames`` received, ``used`` (every sensor valid),
    ``t_pose_at`` (seconds from the first frame used, once a T-pose was found), the
    ``calibration`` and its ``report`` once made, else ``reason`` (why not)."""
    frames: int = 0
    used: int = 0
    t_pose_at: float | None = None
    calibration: SuitCalibration | None = None
    report: dict[str, Any] = field(default_factory=dict)
    reason: str = ""
    #: the rate the device's clock says (Hz) when it is off the declared one, else None
    measured_rate: float | None = None


def capture(source: Any, up: str, seconds: float, hold_s: float = HOLD_S,
            progress: Callable[[str], None] | None = None,
            clock: Callable[[], float] = time.monotonic) -> Capture:
    """Read ``source`` (a started ``rtseg.drivers.base.Source``) for at most ``seconds``
    and calibrate on its frames (module doc).  ``progress`` gets a line when the T-pose is
    found.  The frame rate is the source's, else measured from the frames' receive times."""
    check_source(source)
    names, parents = list(source.joint_names), list(source.parents)
    quats: list[np.ndarray] = []
    times: list[float] = []
    rate_check: DeclaredRateCheck | None = None      # made with the first frame's rate
    out = Capture()
    last_good = np.full(len(names), -np.inf)       # receive time of each sensor's last valid value
    end = clock() + float(seconds)
    next_try = TRY_EVERY_S
    while clock() < end:
        frame = source.read(timeout=0.05)
        if frame is None:
            continue
        out.frames += 1
        now = float(frame.recv_time)
        if rate_check is None:
            rate_check = DeclaredRateCheck(_rate(source, [now]), window_s=RATE_WINDOW_S)
        rate_check.feed(now, frame.source_time, frame.seq)
        valid = np.asarray(frame.valid, dtype=bool)
        last_good[valid] = now
        if not np.all(valid | (now - last_good <= STALE_S)):
            continue                       # a sensor gone longer than STALE_S: left out
        quats.append(np.array(frame.quats, dtype=np.float64))
        times.append(now)
        out.used = len(quats)
        if times[-1] - times[0] < next_try:
            continue
        next_try = times[-1] - times[0] + TRY_EVERY_S
        rate = _rate(source, times)
        if rate_check.on_source_clock and rate_check.mismatch:
            measured = float(rate_check.measured_hz)
            if out.measured_rate is None and progress is not None:
                progress(f"the suit's clock says {measured:.1f} Hz, not the {rate:g} Hz "
                         f"declared: timing the T-pose at {measured:.1f} Hz (add "
                         f"rate={round(measured):g} to the URL)")
            out.measured_rate = rate = measured
        q = np.stack(quats)
        if out.t_pose_at is None:
            still = still_stretch(q, rate, hold_s)
            if still is None:
                continue
            out.t_pose_at = still[0] / rate
            if progress is not None:
                progress(f"T-pose held at {still[0] / rate:.1f}-{still[1] / rate:.1f} s; now "
                         f"bend the knees (squat, walk on the spot)")
        try:
            out.calibration, out.report = calibrate(q, names, parents, rate, up, hold_s)
            return out
        except CalibrationError as exc:
            out.reason = str(exc)
    if not out.reason:
        out.reason = (f"no frame arrived in {seconds:g} s" if not out.frames else
                      f"no frame with every sensor valid in {seconds:g} s" if not out.used else
                      f"no {hold_s:g} s T-pose in {seconds:g} s: hold the T-pose still")
    out.reason += input_losses(source, out)
    return out


def input_losses(source: Any, out: Capture) -> str:
    """What the input lost while the capture read it, as a clause for a failure reason
    ("" when nothing): frames with a sensor invalid (left out, so a T-pose held through
    them is cut short), frames lost and bytes damaged on the link."""
    st = getattr(source, "stats", None)
    parts = []
    if out.frames > out.used:
        parts.append(f"{out.frames - out.used} of {out.frames} frames had a sensor invalid "
                     f"for more than {STALE_S:g} s (left out)")
    for key, what in (("dropped", "frames lost"), ("corrupt", "damaged messages")):
        n = int(getattr(st, key, 0) or 0)
        if n:
            parts.append(f"{n} {what}")
    return f" (the input: {', '.join(parts)})" if parts else ""


def check_source(source: Any) -> None:
    """CalibrationError (one line) unless ``source`` gives raw sensor orientations that a
    suit calibration is for: global orientations, not calibrated already."""
    if getattr(source, "space", "global") != "global":
        raise CalibrationError("the source gives joint rotations, not sensor orientations: "
                               "a suit calibration is for IMU suits (serial://)")
    if getattr(source, "calibration", None) is not None:
        raise CalibrationError("the source is calibrated already: leave calibration= out of "
                               "the URL to record a new one")


def _rate(source: Any, times: list[float]) -> float:
    """The source's declared frame rate, else 1 / the median receive period."""
    rate = getattr(source, "frame_rate", None)
    if rate:
        return float(rate)
    d = np.diff(times)
    d = d[d > 0]
    return 1.0 / float(np.median(d)) if len(d) else 120.0


__all__ = ["Capture", "capture", "input_losses", "check_source", "STALE_S", "TRY_EVERY_S"]
