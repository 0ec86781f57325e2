"""Recording a suit calibration from a live source (``rtseg calibrate``).

The performer holds a T-pose for a second, then bends the knees (a squat, walking on the
spot); :func:`capture` reads the source's frames meanwhile and tries
``rtseg.core.suit_calibration.calibrate`` on what has arrived every half second, until it
succeeds or ``seconds`` have passed.  Frames with any sensor invalid are left out (a
calibration needs every sensor).  The source must give sensor orientations (``space``
"global") and must not be calibrated already (:func:`check_source`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from rtseg.core.suit_calibration import (HOLD_S, CalibrationError, SuitCalibration, calibrate,
                                         still_stretch)

#: seconds of new frames between two attempts
TRY_EVERY_S = 0.5


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
    out = Capture()
    end = clock() + float(seconds)
    next_try = TRY_EVERY_S
    while clock() < end:
        frame = source.read(timeout=0.05)
        if frame is None:
            continue
        out.frames += 1
        if not np.all(frame.valid):
            continue
        quats.append(np.array(frame.quats, dtype=np.float64))
        times.append(float(frame.recv_time))
        out.used = len(quats)
        if times[-1] - times[0] < next_try:
            continue
        next_try = times[-1] - times[0] + TRY_EVERY_S
        rate = _rate(source, times)
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
    return out


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


__all__ = ["Capture", "capture", "check_source", "TRY_EVERY_S"]
