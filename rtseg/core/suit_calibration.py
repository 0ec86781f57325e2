"""Sensor-to-segment calibration of an IMU suit from a T-pose and a few knee bends.

An IMU reports its own orientation q (scalar-last, sensor frame -> the sensor's world),
not its segment's: each sensor sits on its segment at an unknown mounting rotation, and
its world has the fusion's own up axis (Z for a BNO055, Y for most others) and heading
(magnetic north).  Posture naming (``rtseg.core.posture``, ``rtseg.core.standard_rig``) and
behaviour libraries learned from mocap files want each segment's rotation from a T-pose in
rtseg's world: right-handed, Y up, the performer facing +Z with the left at +X
(``tpose=1`` of the serial source).  With

    A    the rotation taking the sensors' world to a Y-up one (``up``: identity for "y",
         -90 degrees about X for "z"),
    psi  the performer's heading in that Y-up world (about +Y, from the knees below),
    B    = R_y(-psi) A,
    q_c  each sensor's orientation while the performer holds the T-pose,

a segment's rotation from the T-pose is

    G(t) = B q(t) q_c^-1 B^-1

(the mounting M = q_c^-1 B^-1 drops out: at the T-pose G is the identity).  A T-pose says
nothing of the heading: orientations alone cannot tell which way arms held out point.
The knees can: a knee bends about the body's left-right axis, and the rotation of a shin
relative to its thigh, taken from the T-pose, is about that axis expressed in the
calibration's world; a positive turn about +left is a flexion (the foot goes back).  So
``psi`` comes from the knee bends after the T-pose, and a knee axis that is far from
horizontal says the ``up`` given is wrong.

:func:`calibrate` finds both in a recorded stretch of frames (``rtseg calibrate`` records
one from a live source); :class:`SuitCalibration` applies the result to every frame and is
saved as JSON (``save`` / ``load``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from rtseg.core import quat
from rtseg.core.rig import map_rig

FORMAT = "rtseg-suit-calibration"
VERSION = 1
#: the sensors' world up axis -> the rotation A taking it to Y up (scalar-last)
UP_AXES: dict[str, tuple[float, float, float, float]] = {
    "y": (0.0, 0.0, 0.0, 1.0),
    "z": (-math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)),
}
#: seconds the T-pose must be held, every sensor within :data:`STILL_DEG` of where it was
HOLD_S = 1.0
STILL_DEG = 5.0
#: a knee counts as bent beyond this angle (degrees) from its T-pose
BENT_DEG = 30.0
#: knee bends (frames, both knees counted) the heading is taken from, at least
MIN_BENT = 30
#: the bends' axes must agree: length of their mean unit axis (1 = all the same)
AGREE = 0.8
#: the mean knee axis may rise at most this far from horizontal (degrees) before ``up`` is
#: judged wrong
MAX_TILT_DEG = 30.0
#: a calibration's reference quaternions must have length 1 within this (a file's are
#: rounded to 8 decimals; a zero or hand-edited row is refused, not silently renormalised)
UNIT_TOL = 1e-3


class CalibrationError(ValueError):
    """A calibration that cannot be made or read (one line: what is missing or wrong)."""


def _yaw(psi: float) -> np.ndarray:
    """Rotation by ``psi`` radians about +Y (scalar-last)."""
    return np.array([0.0, math.sin(psi / 2), 0.0, math.cos(psi / 2)])


def world_rotation(up: str, heading_deg: float) -> np.ndarray:
    """B = R_y(-psi) A of the module doc (scalar-last): the sensors' world (up axis
    ``up``) to rtseg's, the performer (heading ``heading_deg``) facing +Z."""
    if up not in UP_AXES:
        raise CalibrationError(f"up={up!r}: one of {', '.join(UP_AXES)}")
    return quat.multiply(_yaw(-math.radians(heading_deg)), np.array(UP_AXES[up]))


@dataclass(frozen=True)
class SuitCalibration:
    """A suit's calibration (module doc): ``joint_names`` in the source's order,
    ``reference`` (J, 4) each sensor's orientation in the T-pose, ``up`` the sensors' world
    up axis ("y" or "z"), ``heading_deg`` the performer's heading psi in degrees."""
    joint_names: tuple[str, ...]
    reference: np.ndarray
    up: str
    heading_deg: float

    def __post_init__(self) -> None:
        ref = np.asarray(self.reference, dtype=np.float64)
        if ref.shape != (len(self.joint_names), 4) or not np.isfinite(ref).all():
            raise CalibrationError(f"calibration reference must be ({len(self.joint_names)}, 4) "
                                   f"finite quaternions, got shape {ref.shape}")
        off = np.flatnonzero(np.abs(np.linalg.norm(ref, axis=1) - 1.0) > UNIT_TOL)
        if len(off):
            raise CalibrationError(f"calibration reference of {self.joint_names[off[0]]} is not "
                                   f"a unit quaternion (length "
                                   f"{np.linalg.norm(ref[off[0]]):.3g})")
        if self.up not in UP_AXES:
            raise CalibrationError(f"calibration up={self.up!r}: one of {', '.join(UP_AXES)}")
        if not math.isfinite(self.heading_deg):
            raise CalibrationError(f"calibration heading_deg must be a finite number of degrees, "
                                   f"got {self.heading_deg!r}")
        object.__setattr__(self, "reference", quat.normalize(ref))
        b = world_rotation(self.up, self.heading_deg)
        # G = B q (q_c^-1 B^-1): a left factor for all, a right factor per sensor
        object.__setattr__(self, "_left", b)
        object.__setattr__(self, "_right", quat.multiply(quat.conjugate(self.reference),
                                                         quat.conjugate(b)[None, :]))

    def apply(self, quats: np.ndarray) -> np.ndarray:
        """Sensor orientations (..., J, 4) -> each segment's rotation from the T-pose in
        rtseg's world (..., J, 4), scalar-last (module doc)."""
        q = np.asarray(quats, dtype=np.float64)
        return quat.multiply(quat.multiply(self._left, q), self._right)

    def as_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "version": VERSION, "joints": list(self.joint_names),
                "up": self.up, "heading_deg": round(float(self.heading_deg), 4),
                "reference": [[round(float(v), 8) for v in row] for row in self.reference]}

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.as_dict(), indent=1) + "\n", encoding="utf-8")

    @classmethod
    def load(cls, path: str | Path) -> "SuitCalibration":
        """Read a file :meth:`save` wrote; CalibrationError (one line) for anything else."""
        try:
            doc = json.loads(Path(path).read_text(encoding="utf-8"))
        except OSError as exc:
            raise CalibrationError(f"calibration {path}: cannot read ({exc.strerror})") from None
        except ValueError as exc:
            raise CalibrationError(f"calibration {path}: not JSON ({exc})") from None
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise CalibrationError(f"calibration {path}: not an rtseg suit calibration "
                                   f"(rtseg calibrate writes one)")
        if doc.get("version") != VERSION:
            raise CalibrationError(f"calibration {path}: version {doc.get('version')!r}, this "
                                   f"rtseg reads {VERSION}")
        try:
            return cls(tuple(str(j) for j in doc["joints"]), np.asarray(doc["reference"], float),
                       str(doc["up"]), float(doc["heading_deg"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise CalibrationError(f"calibration {path}: malformed ({exc})") from None

    def check_joints(self, joint_names: Sequence[str], where: str = "") -> None:
        """CalibrationError unless the source's joints are the calibrated ones, in order."""
        if tuple(joint_names) != self.joint_names:
            raise CalibrationError(f"{where + ': ' if where else ''}the calibration is of a suit "
                                   f"with sensors {', '.join(self.joint_names)}, this one has "
                                   f"{', '.join(joint_names)}: calibrate it (rtseg calibrate)")


def still_stretch(quats: np.ndarray, frame_rate: float, hold_s: float = HOLD_S,
                  still_deg: float = STILL_DEG) -> tuple[int, int] | None:
    """The first frames [a, b) of ``quats`` (N, J, 4), ``hold_s`` seconds long, in which
    every sensor stays within ``still_deg`` of its orientation at frame a; None if none."""
    q = quat.normalize(np.asarray(quats, dtype=np.float64))
    need = max(2, int(round(hold_s * frame_rate)))
    cos_half = math.cos(math.radians(still_deg) / 2)
    a = 0
    while a + need <= len(q):
        dots = np.abs(np.einsum("njk,jk->nj", q[a:a + need], q[a]))   # |cos(angle / 2)|
        moved = np.flatnonzero((dots < cos_half).any(axis=1))
        if not len(moved):
            return a, a + need
        a += int(moved[0])
    return None


def knee_heading(rotations: np.ndarray, joint_names: Sequence[str], parents: Sequence[int]
                 ) -> tuple[float, int, float]:
    """(heading psi in degrees, knee bends used, tilt of their mean axis from horizontal in
    degrees) from ``rotations`` (N, J, 4): each segment's rotation from the T-pose in a
    Y-up world of unknown heading (module doc).  CalibrationError when fewer than
    :data:`MIN_BENT` bends, when they disagree, or when their axis is not horizontal."""
    rig = map_rig(list(joint_names), list(parents), "calibration")
    g = np.asarray(rotations, dtype=np.float64)
    axes = []
    for side in ("left", "right"):
        thigh, shin = rig.index[f"{side}_upper_leg"], rig.index[f"{side}_lower_leg"]
        rel = quat.multiply(quat.conjugate(g[:, thigh]), g[:, shin])     # shin from thigh
        w = np.clip(rel[:, 3], -1.0, 1.0)
        angle = 2.0 * np.degrees(np.arccos(np.abs(w)))
        v = rel[:, :3] * np.sign(w + (w == 0))[:, None]                  # axis x sin, w >= 0
        bent = angle > BENT_DEG
        axes.append(v[bent] / np.linalg.norm(v[bent], axis=1, keepdims=True))
    ax = np.concatenate(axes)
    if len(ax) < MIN_BENT:
        raise CalibrationError(f"{len(ax)} knee bends beyond {BENT_DEG:g} degrees after the "
                               f"T-pose, {MIN_BENT} needed: bend the knees (squat, walk on the "
                               f"spot) after holding the T-pose")
    mean = ax.mean(axis=0)
    agree = float(np.linalg.norm(mean))
    if agree < AGREE:
        raise CalibrationError(f"the knees bent about different axes (agreement {agree:.2f}, "
                               f"{AGREE} needed): did the sensors move on the body?")
    left = mean / agree
    tilt = float(np.degrees(np.arcsin(min(1.0, abs(left[1])))))
    if tilt > MAX_TILT_DEG:
        raise CalibrationError(f"the knees bend about an axis {tilt:.0f} degrees from "
                               f"horizontal: the sensors' up axis is not the one given")
    # left = R_y(psi) (1, 0, 0) = (cos psi, 0, -sin psi)
    return math.degrees(math.atan2(-left[2], left[0])), len(ax), tilt


def calibrate(quats: np.ndarray, joint_names: Sequence[str], parents: Sequence[int],
              frame_rate: float, up: str = "y", hold_s: float = HOLD_S,
              still_deg: float = STILL_DEG) -> tuple[SuitCalibration, dict[str, Any]]:
    """The calibration of a suit from its sensor orientations ``quats`` (N, J, 4): the
    first T-pose held ``hold_s`` seconds, then knee bends for the heading.  Returns it and
    a report (frames of the T-pose, bends, tilt).  CalibrationError (one line) when the
    frames hold no T-pose or too few knee bends after it."""
    if up not in UP_AXES:
        raise CalibrationError(f"up={up!r}: one of {', '.join(UP_AXES)}")
    q = quat.make_continuous(quat.normalize(np.asarray(quats, dtype=np.float64)), axis=0)
    still = still_stretch(q, frame_rate, hold_s, still_deg)
    if still is None:
        raise CalibrationError(f"no {hold_s:g} s in {len(q) / frame_rate:.1f} s with every "
                               f"sensor still (within {still_deg:g} degrees): hold the T-pose")
    a, b = still
    ref = quat.normalize(q[a:b].mean(axis=0))
    flat = SuitCalibration(tuple(joint_names), ref, up, 0.0)
    psi, bends, tilt = knee_heading(flat.apply(q[b:]), joint_names, parents)
    cal = SuitCalibration(tuple(joint_names), ref, up, psi)
    return cal, {"t_pose_frames": [int(a), int(b)], "knee_bends": bends,
                 "knee_axis_tilt_deg": round(tilt, 2), "heading_deg": round(psi, 2)}


__all__ = ["CalibrationError", "SuitCalibration", "calibrate", "knee_heading", "world_rotation",
           "still_stretch", "UP_AXES", "HOLD_S", "STILL_DEG", "MIN_BENT"]
