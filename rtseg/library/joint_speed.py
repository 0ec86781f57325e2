"""How fast each joint turns over a window: the tempo half of a library window's body
descriptor (``rtseg.library.posture_distance``).

A window of pose-feature rows (``rtseg.core.features``: per joint its parent-relative unit
quaternion, 4 values, frames in order, at ``frame_rate`` Hz) gives per joint the median,
over the window's consecutive frames, of the angle turned from one frame to the next times
the frame rate (rad/s), stated as log(1 + speed).  The median is the speed the joint keeps
up, not its bursts: a hand waved turns the forearm 100-200 deg/s the whole time, a hand
raised and held moves in two bursts and rests between them (Bandai's two actors:
forearm median 104-204 deg/s waving, 36-97 deg/s raising), which is true of both actors
however high each lifts the arm.  Seconds, not frames: the same motion at 30 and 120 fps
gives the same values.
"""

from __future__ import annotations

import numpy as np

#: the weight of the joint speeds beside the posture's mean and spread in a library
#: window's descriptor (``rtseg.library.posture_distance``): chosen leave-one-person-out
#: over the eight scored people of ``benchmarks/library_loto.py --by-person
#: ../shared/data`` among 0, 0.5, 0.75, 1, 1.5 and 2 (docs/identity.md)
SPEED_WEIGHT = 1.0


def joint_speeds(W: np.ndarray, frame_rate: float) -> np.ndarray:
    """log(1 + median angular speed, rad/s) of each joint, (dims / 4,), over the feature
    rows W (frames >= 2, dims a multiple of 4) sampled at ``frame_rate`` Hz.  The angle
    between consecutive quaternions q, p is 4 asin(|q - s p| / 2), s the sign of q . p
    (q and -q are one rotation), exact for small angles where acos is not."""
    W = np.asarray(W, dtype=np.float64)
    if W.ndim != 2 or W.shape[1] % 4 or len(W) < 2:
        raise ValueError(f"joint speeds need (frames >= 2, 4 x joints) rows, got {W.shape}")
    if not frame_rate > 0:
        raise ValueError(f"frame rate must be positive, got {frame_rate}")
    Q = W.reshape(len(W), -1, 4)
    a, b = Q[1:], Q[:-1]
    sign = np.where(np.einsum("tjk,tjk->tj", a, b) < 0.0, -1.0, 1.0)
    chord = np.linalg.norm(a - sign[..., None] * b, axis=2)
    angle = 4.0 * np.arcsin(np.minimum(chord * 0.5, 1.0))
    return np.log1p(np.median(angle, axis=0) * float(frame_rate))
